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


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
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
    # Loss and gradient from one compiled program, which the finite difference
    # evaluates too (a separately compiled forward run would cost another compile).
    @eqx.filter_jit
    @eqx.filter_value_and_grad
    def loss_and_gradient(potential):
        run = lj.simulate(make_system(potential), START, t1=2.0, **options)
        return jnp.sum(run.q[-1] ** 2)

    loss = lambda potential: loss_and_gradient(potential)[0]
    gradient = loss_and_gradient(POTENTIAL)[1]
    for leaf_of in (lambda m: m.stiffness, lambda m: m.anharmonicity):
        expected = _finite_difference(loss, POTENTIAL, leaf_of)
        assert abs(float(expected)) > 1e-3  # a real dependence, not a zero
        np.testing.assert_allclose(leaf_of(gradient), expected, rtol=1e-6)


def _stiffness_of(model):
    return model.potential.stiffness


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_lagrangian_module_gradient_and_parameter_recovery():
    # A pendulum-like anharmonic oscillator: learn the stiffness from its own
    # trajectory by Gauss-Newton-free gradient descent on a 1-D quadratic bowl.
    truth = LagrangianNet(jnp.asarray(1.0), POTENTIAL)
    ts = jnp.linspace(0.0, 2.0, 21)

    def trajectory(model):
        return lj.simulate(lj.Lagrangian(model), START, t1=2.0, dt=0.01, ts=ts).q

    data = trajectory(truth)

    def loss(model):
        return jnp.mean((trajectory(model) - data) ** 2)

    # The loss, its gradient on every weight, and the curvature along the stiffness
    # (forward over reverse mode): one compile for the gradient check and for every
    # Newton step.
    along_stiffness = eqx.tree_at(
        _stiffness_of, jax.tree_util.tree_map(jnp.zeros_like, truth), jnp.asarray(1.0)
    )

    @eqx.filter_jit
    def loss_gradient_curvature(model):
        value_and_gradient = eqx.filter_value_and_grad(loss)
        primal, tangent = eqx.filter_jvp(
            value_and_gradient, (model,), (along_stiffness,)
        )
        (value, gradient), curvature = primal, tangent[1]
        return value, gradient, _stiffness_of(curvature)

    with_stiffness = lambda k: eqx.tree_at(_stiffness_of, truth, k)
    model = with_stiffness(jnp.asarray(1.6))
    _, gradient, _ = loss_gradient_curvature(model)
    expected = _finite_difference(
        lambda m: loss_gradient_curvature(m)[0], model, _stiffness_of
    )
    np.testing.assert_allclose(_stiffness_of(gradient), expected, rtol=1e-6)
    # Newton's method on the scalar stiffness, with the curvature by autodiff.
    k = jnp.asarray(1.6)
    for _ in range(8):
        _, gradient, curvature = loss_gradient_curvature(with_stiffness(k))
        k = k - _stiffness_of(gradient) / curvature
    assert abs(float(k) - 2.0) < 1e-6


def test_plain_functions_still_share_compilation():
    # Two systems of the same plain function are equal (static structure).
    potential = lambda q: 0.5 * q**2
    assert _separable(potential) == _separable(potential)
    system = _separable(POTENTIAL)
    leaves = jax.tree_util.tree_leaves(eqx.filter(system, eqx.is_array))
    assert len(leaves) == 2  # the two weights, and nothing else
