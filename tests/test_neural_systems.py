"""Neural networks as the L or H of a system, trained through `simulate`.

Oracles: central finite differences of the same loss (float64); the published
Lagrangian-neural-network formula (Cranmer et al. 2020: Hessian and pseudo-inverse),
an independent route to the same q̈; and a pendulum's g and l recovered from its own
trajectory.
"""

import warnings

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.mechanics.neural import network_acceleration

START = (jnp.array([0.4, -0.3]), jnp.array([0.2, 0.5]))


class LagrangianNet(eqx.Module):
    """L(q, q̇) = ½|q̇|² + MLP([q, q̇]): an LNN with a well-conditioned mass matrix."""

    mlp: eqx.nn.MLP

    def __call__(self, q, qdot):
        return 0.5 * qdot @ qdot + 0.1 * self.mlp(jnp.concatenate([q, qdot]))


class HamiltonianNet(eqx.Module):
    """H(q, p) = ½|p|² + MLP([q, p]): an HNN."""

    mlp: eqx.nn.MLP

    def __call__(self, q, p):
        return 0.5 * p @ p + 0.1 * self.mlp(jnp.concatenate([q, p]))


def _mlp(seed):
    return eqx.nn.MLP(4, "scalar", 8, 1, activation=jnp.tanh, key=jax.random.key(seed))


def _first_weight(net):
    return net.mlp.layers[0].weight


def _finite_difference(loss, net, index, step=1e-6):
    def shifted(delta):
        weight = _first_weight(net).at[index].add(delta)
        return loss(eqx.tree_at(_first_weight, net, weight))

    return (shifted(step) - shifted(-step)) / (2 * step)


def _check_against_finite_differences(loss, net):
    # One compilation serves the gradient and every finite-difference evaluation.
    value_and_grad = eqx.filter_jit(eqx.filter_value_and_grad(loss))
    gradient = _first_weight(value_and_grad(net)[1])
    for index in [(0, 0), (3, 2), (7, 3)]:
        expected = _finite_difference(lambda n: value_and_grad(n)[0], net, index)
        assert abs(float(expected)) > 1e-6  # a real dependence, not a zero
        np.testing.assert_allclose(gradient[index], expected, rtol=1e-6, atol=1e-12)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "make_system, options",
    [
        (
            lambda n: lj.Lagrangian(LagrangianNet(n)),
            dict(dt=0.05, solver=diffrax.Tsit5()),
        ),
        (lambda n: lj.Hamiltonian(HamiltonianNet(n)), dict(dt=0.05)),
    ],
    ids=["LNN-fixed-Tsit5", "HNN-GaussLegendre"],
)
def test_mlp_gradient_through_simulate_matches_finite_differences(make_system, options):
    def loss(net):
        run = lj.simulate(make_system(net.mlp), START, t1=0.3, **options)
        return jnp.sum(run.q[-1] ** 2) + jnp.sum(run.ys[1][-1] ** 2)

    _check_against_finite_differences(loss, LagrangianNet(_mlp(0)))


def _published_lnn_acceleration(lagrangian, q, qdot):
    """Cranmer et al. (2020), eq. 6: pinv(∇q̇∇q̇ᵀL) (∇qL − (∇q∇q̇ᵀL) q̇)."""
    mass = jax.hessian(lagrangian, argnums=1)(q, qdot)
    mixed = jax.jacobian(jax.jacobian(lagrangian, argnums=1), argnums=0)(q, qdot)
    force = jax.grad(lagrangian, argnums=0)(q, qdot)
    return jnp.linalg.pinv(mass) @ (force - mixed @ qdot)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_lnn_acceleration_loss_matches_published_formula_and_gradient():
    net = LagrangianNet(_mlp(1))
    keys = jax.random.split(jax.random.key(2), 3)
    q, qdot, target = (jax.random.normal(k, (16, 2)) for k in keys)

    def loss(acceleration, network):
        predicted = jax.vmap(lambda a, b: acceleration(network, a, b))(q, qdot)
        return jnp.mean((predicted - target) ** 2)

    def derived(network, a, b):
        return lj.Lagrangian(network).acceleration(a, b)

    @eqx.filter_jit  # one compilation for the three batches (eager vmap dispatches op by op)
    def accelerations(network):
        return [
            jax.vmap(f, in_axes=(None, 0, 0))(network, q, qdot)
            for f in (derived, network_acceleration, _published_lnn_acceleration)
        ]

    mine, fused, published = accelerations(net)
    np.testing.assert_allclose(mine, published, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(fused, published, rtol=1e-10, atol=1e-12)
    # The gradient of the loss through `Lagrangian.acceleration` (a Module with
    # arrays: the network formulation) against finite differences.
    _check_against_finite_differences(lambda n: loss(derived, n), net)


class Pendulum(eqx.Module):
    """L = ½ l² θ̇² + g l cos θ (unit mass), with trainable g and l."""

    gravity: jax.Array
    length: jax.Array

    def __call__(self, theta, omega):
        return 0.5 * self.length**2 * omega**2 + self.gravity * self.length * jnp.cos(
            theta
        )


def _bob_positions(model, ts):
    # θ(t) alone fixes only g/l; the bob's Cartesian path fixes l (its radius) too.
    run = lj.simulate(
        lj.Lagrangian(model),
        (jnp.asarray(1.0), jnp.asarray(0.0)),
        t1=2.0,
        dt=0.01,
        ts=ts,
        solver=diffrax.Tsit5(),
    )
    return jnp.stack([model.length * jnp.sin(run.q), -model.length * jnp.cos(run.q)])


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_training_recovers_pendulum_gravity_and_length():
    ts = jnp.linspace(0.0, 2.0, 41)
    truth = jnp.array([9.81, 1.0])
    data = _bob_positions(Pendulum(*truth), ts)

    def residuals(params):
        return (_bob_positions(Pendulum(*params), ts) - data).ravel()

    def loss(params):
        return jnp.mean(residuals(params) ** 2)

    params = jnp.array([8.5, 1.2])
    initial_loss = loss(params)
    jacobian = jax.jit(jax.jacrev(residuals))  # reverse mode through simulate
    for _ in range(10):  # Gauss–Newton
        step, *_ = jnp.linalg.lstsq(jacobian(params), residuals(params))
        params = params - step
    assert loss(params) < 1e-12 * initial_loss
    np.testing.assert_allclose(params, truth, atol=1e-6)


class FrozenPotential(eqx.Module):
    """A Module whose weight is marked static: it would be frozen (its gradient
    absent, the weight itself returned in the gradient's place)."""

    stiffness: jax.Array = eqx.field(static=True)

    def __call__(self, q):
        return 0.5 * self.stiffness * q**2


class LagrangianWithFrozenPart(eqx.Module):
    mass: jax.Array
    parts: tuple

    def __call__(self, q, qdot):
        return 0.5 * self.mass * qdot**2 - self.parts[0](q)


@pytest.mark.parametrize(
    "make_system, field",
    [
        (
            lambda frozen: lj.SeparableHamiltonian(lambda p: 0.5 * p**2, frozen),
            "FrozenPotential.stiffness",
        ),
        (
            lambda frozen: lj.Lagrangian(
                LagrangianWithFrozenPart(jnp.asarray(1.0), (frozen,))
            ),
            "LagrangianWithFrozenPart.parts.stiffness",
        ),
    ],
    ids=["potential", "nested"],
)
def test_static_array_in_a_module_is_refused_naming_the_field(make_system, field):
    with pytest.warns(UserWarning, match="JAX array is being set as static"):
        frozen = FrozenPotential(jnp.asarray(2.0))  # equinox only warns
    with pytest.raises(ValueError, match=f"{field} is a JAX array in a static field"):
        make_system(frozen)


def test_closed_over_parameter_gets_its_gradient_not_a_zero():
    # A plain function is static structure; a parameter it closes over is still
    # traced by JAX, so its gradient is exact, not silently 0.
    def loss(stiffness):
        system = lj.SeparableHamiltonian(
            lambda p: 0.5 * p**2, lambda q: 0.5 * stiffness * q**2
        )
        run = lj.simulate(system, (jnp.asarray(0.7), jnp.asarray(0.0)), t1=1.0, dt=0.01)
        return run.q[-1] ** 2

    # Exact for the harmonic oscillator: q(1) = 0.7 cos(√k), d/dk q² = −0.49 sin(2√k)/(2√k).
    k = 2.0
    expected = -0.49 * np.sin(2 * np.sqrt(k)) / (2 * np.sqrt(k))
    np.testing.assert_allclose(jax.grad(loss)(k), expected, rtol=1e-6)


def test_undifferentiable_numpy_function_raises():
    system = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: -np.cos(q))

    def final_angle(q0):
        return lj.simulate(system, (q0, jnp.asarray(0.0)), t1=1.0, dt=0.01).q[-1]

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(TypeError, match="NumPy"):
            jax.grad(final_angle)(0.5)
