"""Equinox Modules as the functions of a system: their weights are trainable.

The oracle is a central finite difference of the same loss (the gradient of a
smooth loss through a fixed-step or adaptive solve is that derivative to the
solver's round-off), and a parameter recovered from data generated with it.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj


class Quadratic(eqx.Module):
    """V(q) = ½ k q² + a q⁴ with trainable k and a: a two-weight 'network'."""

    stiffness: jax.Array
    anharmonicity: jax.Array

    def __call__(self, q):
        return 0.5 * self.stiffness * q**2 + self.anharmonicity * q**4


class LagrangianNet(eqx.Module):
    """L = ½ m q̇² − V(q) with V a Module inside a Module."""

    mass: jax.Array
    potential: Quadratic

    def __call__(self, q, qdot):
        return 0.5 * self.mass * qdot**2 - self.potential(q)


POTENTIAL = Quadratic(jnp.asarray(2.0), jnp.asarray(0.1))
START = (jnp.asarray(0.7), jnp.asarray(0.0))


def _finite_difference(loss, model, leaf_of, step=1e-6):
    plus = eqx.tree_at(leaf_of, model, leaf_of(model) + step)
    minus = eqx.tree_at(leaf_of, model, leaf_of(model) - step)
    return (loss(plus) - loss(minus)) / (2 * step)


def _kinetic(p):
    return 0.5 * p**2


def _separable(potential):
    return lj.SeparableHamiltonian(_kinetic, potential)


@pytest.mark.parametrize(
    "make_system, options",
    [
        (_separable, dict(dt=0.01, solver=lj.Yoshida4())),
        (_separable, dict(solver=diffrax.Tsit5(), rtol=1e-10, atol=1e-10)),
        (lambda v: lj.Hamiltonian(lambda q, p: 0.5 * p**2 + v(q)), dict(dt=0.01)),
    ],
    ids=["separable-Yoshida4", "separable-Tsit5", "Hamiltonian-GaussLegendre"],
)
def test_gradient_through_simulate_reaches_the_weights(make_system, options):
    def loss(potential):
        run = lj.simulate(make_system(potential), START, t1=2.0, **options)
        return jnp.sum(run.q[-1] ** 2)

    gradient = eqx.filter_grad(loss)(POTENTIAL)
    for leaf_of in (lambda m: m.stiffness, lambda m: m.anharmonicity):
        expected = _finite_difference(loss, POTENTIAL, leaf_of)
        assert abs(float(expected)) > 1e-3  # a real dependence, not a zero
        np.testing.assert_allclose(leaf_of(gradient), expected, rtol=1e-6)


def test_lagrangian_module_gradient_and_parameter_recovery():
    # A pendulum-like anharmonic oscillator: learn the stiffness from its own
    # trajectory by Gauss-Newton-free gradient descent on a 1-D quadratic bowl.
    truth = LagrangianNet(jnp.asarray(1.0), POTENTIAL)
    ts = jnp.linspace(0.0, 2.0, 21)

    def trajectory(model):
        return lj.simulate(lj.Lagrangian(model), START, t1=2.0, dt=0.01, ts=ts).q

    data = trajectory(truth)

    # Compiled once each: the eager versions re-traced simulate on every call.
    @eqx.filter_jit
    def loss(model):
        return jnp.mean((trajectory(model) - data) ** 2)

    model = eqx.tree_at(lambda m: m.potential.stiffness, truth, jnp.asarray(1.6))
    gradient = eqx.filter_jit(eqx.filter_grad(loss))(model)
    expected = _finite_difference(loss, model, lambda m: m.potential.stiffness)
    np.testing.assert_allclose(gradient.potential.stiffness, expected, rtol=1e-6)
    # Newton's method on the scalar stiffness, with the curvature by autodiff.
    stiffness_loss = lambda k: loss(
        eqx.tree_at(lambda m: m.potential.stiffness, model, k)
    )
    newton_step = jax.jit(
        lambda k: k - jax.grad(stiffness_loss)(k) / jax.hessian(stiffness_loss)(k)
    )
    k = jnp.asarray(1.6)
    for _ in range(8):
        k = newton_step(k)
    assert abs(float(k) - 2.0) < 1e-6


def test_plain_functions_still_share_compilation():
    # Two systems of the same plain function are equal (static structure).
    potential = lambda q: 0.5 * q**2
    assert _separable(potential) == _separable(potential)
    system = _separable(POTENTIAL)
    leaves = jax.tree_util.tree_leaves(eqx.filter(system, eqx.is_array))
    assert len(leaves) == 2  # the two weights, and nothing else
