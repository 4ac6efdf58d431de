"""The batch-native Taylor integrator (`lagjax.taylor.batch`): the scalar graph's
coefficients against `jax.experimental.jet`, each member's result against its own
one-trajectory run, per-member steps and saves, batched parameters, refusals."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.experimental import jet

import lagjax as lj
from lagjax.taylor import RESULTS, taylor_integrate
from lagjax.taylor.batch import taylor_integrate_batch
from lagjax.taylor.coefficients import graph_coefficients, lower_vector_field

G = 9.81
LAGRANGIAN = lj.Lagrangian(
    lambda q, qd: (
        qd[0] ** 2
        + 0.5 * qd[1] ** 2
        + qd[0] * qd[1] * jnp.cos(q[0] - q[1])
        + 2 * G * jnp.cos(q[0])
        + G * jnp.cos(q[1])
    )
)


def double_pendulum(t, y, args):
    return jnp.concatenate([y[2:], LAGRANGIAN.acceleration(y[:2], y[2:], t, args)])


def pendulum(t, y, g):
    return jnp.stack([y[1], -g * jnp.sin(y[0])])


def _jet_coefficients(f, y0, order):
    derivatives = [f(y0)]
    for _ in range(2, order + 1):
        _, series = jet.jet(f, (y0,), (derivatives,))
        derivatives.append(series[-1])
    return jnp.stack(
        [y0] + [d / math.factorial(k) for k, d in enumerate(derivatives, 1)]
    )


def test_scalar_graph_coefficients_of_a_batch_match_jet():
    y0s = jnp.array([[0.5, 0.3, 0.1, -0.2], [1.0, -0.4, 0.0, 0.3], [0.1, 0.2, 0, 0]])
    graph, leaves = lower_vector_field(double_pendulum, 0.0, y0s[0], None, scalar=True)
    assert graph.scalar
    assert all(graph.avals[i].shape == () for op in graph.ops for i in op.outs)
    ours = jax.jit(
        lambda y: graph_coefficients(
            graph, jnp.zeros(3), y.T, leaves, 6, unroll=False, batched_leaves=()
        )
    )(y0s)
    f = lambda y: double_pendulum(0.0, y, None)
    for member, y0 in enumerate(y0s):
        by_jet = _jet_coefficients(f, y0, 6)
        scale = jnp.max(jnp.abs(by_jet), axis=1, keepdims=True)
        assert jnp.max(jnp.abs(ours[..., member] - by_jet) / scale) < 1e-13


@pytest.fixture(scope="module")
def pendulum_batch():
    y0s = jnp.stack([jnp.linspace(0.2, 2.5, 5), jnp.zeros(5)], axis=1)
    gs = jnp.array([1.0, 2.0, 0.5, 1.5, 3.0])
    ts = jnp.linspace(0.0, 6.0, 4)
    run = jax.jit(
        lambda y0s, gs: taylor_integrate_batch(
            pendulum, y0s, 0.0, 6.0, ts=ts, args=gs, args_axis=0, rtol=1e-13,
            atol=1e-13,
        )
    )  # fmt: skip
    return y0s, gs, ts, run(y0s, gs)


def test_each_member_matches_its_own_run(pendulum_batch):
    y0s, gs, ts, batch = pendulum_batch
    assert batch.ys.shape == (5, 4, 2)
    assert bool(jnp.all(batch.result == RESULTS.successful))
    one = jax.jit(
        jax.vmap(
            lambda y0, g: taylor_integrate(
                pendulum, y0, 0.0, 6.0, ts=ts, args=g, rtol=1e-13, atol=1e-13
            )
        )
    )(y0s, gs)
    # The same method and step rule: the same steps, the same numbers to rounding.
    np.testing.assert_array_equal(batch.num_steps, one.num_steps)
    np.testing.assert_allclose(batch.ys, one.ys, rtol=0, atol=1e-13)
    # Members take their own steps: faster pendulums need more.
    assert len(set(np.asarray(batch.num_steps).tolist())) > 1


def test_energy_of_every_member_is_kept(pendulum_batch):
    _, gs, _, batch = pendulum_batch
    theta, omega = batch.ys[..., 0], batch.ys[..., 1]
    energy = 0.5 * omega**2 - gs[:, None] * jnp.cos(theta)
    assert float(jnp.max(jnp.abs(energy - energy[:, :1]))) < 1e-12


def test_many_saves_per_member_follow_the_oscillator():
    oscillator = lambda t, y, args: jnp.stack([y[1], -y[0]])
    ts = jnp.linspace(0.0, 5.0, 41)  # more than SMALL_SAVES: the inner saving loop
    y0s = jnp.array([[1.0, 0.0], [0.0, 2.0]])
    run = taylor_integrate_batch(oscillator, y0s, 0.0, 5.0, ts=ts)
    exact = jnp.stack(
        [jnp.cos(ts), -jnp.sin(ts), 2 * jnp.sin(ts), 2 * jnp.cos(ts)], axis=1
    ).reshape(41, 2, 2)
    np.testing.assert_allclose(run.ys, jnp.moveaxis(exact, 1, 0), rtol=0, atol=1e-13)


def test_max_steps_is_reported_per_member():
    y0s = jnp.array([[0.1, 0.0], [2.5, 0.0]])
    run = taylor_integrate_batch(
        pendulum, y0s, 0.0, 50.0, args=1.0, rtol=1e-12, atol=1e-12, max_steps=3
    )
    assert bool(jnp.all(run.result == RESULTS.max_steps_reached))
    assert bool(jnp.all(jnp.isnan(run.ys)))


def test_a_single_state_is_refused_with_the_remedy():
    with pytest.raises(TypeError, match="taylor_integrate"):
        taylor_integrate_batch(pendulum, jnp.ones(2), 0.0, 1.0, args=1.0)
