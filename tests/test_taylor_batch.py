"""The batch-native Taylor integrator (`lagjax.taylor.batch`): the scalar graph's
coefficients on the tape against nested `jax.jvp` and the vector graph (itself
checked against `jax.experimental.jet`), each member's result against its own
one-trajectory run, per-member steps and saves, batched parameters, refusals."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.taylor import RESULTS, taylor_integrate
from lagjax.taylor.batch import taylor_integrate_batch
from lagjax.taylor.coefficients import graph_coefficients, lower_vector_field
from lagjax.taylor.tape import tape_shape
from tests.helpers import lie_coefficients

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


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_scalar_graph_coefficients_of_a_batch_match_the_vector_graph():
    y0s = jnp.array([[0.5, 0.3, 0.1, -0.2], [1.0, -0.4, 0.0, 0.3], [0.1, 0.2, 0, 0]])
    graph, leaves = lower_vector_field(double_pendulum, 0.0, y0s[0], None, scalar=True)
    assert graph.scalar
    assert all(graph.avals[i].shape == () for op in graph.ops for i in op.outs)
    ours = jax.jit(
        lambda y: graph_coefficients(
            graph, jnp.zeros(3), y.T, leaves, 8, unroll=False, batched_leaves=()
        )
    )(y0s)
    vector_graph, _ = lower_vector_field(double_pendulum, 0.0, y0s[0], None)
    # the vector graph's sweep is checked against jet and nested jvp in test_taylor
    by_vector = jax.jit(
        jax.vmap(
            lambda y0: graph_coefficients(
                vector_graph, 0.0, y0, leaves, 8, unroll=False
            )
        )
    )(y0s)
    scale = jnp.max(jnp.abs(by_vector), axis=2, keepdims=True)
    error = jnp.abs(jnp.moveaxis(ours, -1, 0) - by_vector) / scale
    assert jnp.max(error) < 1e-13


def _every_rule(t, y, args):
    a, b = y[0], y[1]
    return jnp.stack(
        [
            jnp.exp(0.3 * a) * jnp.log(2.0 + b) + jnp.sqrt(1.5 + a) / (2.0 + b**2)
            + jnp.tan(0.2 * a) - jnp.tanh(b) + (1.2 + a) ** 1.7,
            jnp.abs(a - 3.0) + jnp.maximum(b, -5.0) + jnp.expm1(0.1 * b)
            + jnp.log1p(0.5 + 0.1 * a) + a**-2 + jnp.cbrt(4.0 + b) + t * a
            + jax.lax.rsqrt(2.0 + b),
        ]
    )  # fmt: skip


@pytest.mark.integration  # nested jvp to order 5: a long compilation
def test_every_rule_on_the_tape_matches_nested_jvp():
    y0s = jnp.array([[0.7, -0.4], [0.2, 0.3]])
    graph, leaves = lower_vector_field(_every_rule, 0.0, y0s[0], None, scalar=True)
    census = set(graph.census())
    assert {"Exp", "Log", "Power", "Sqrt", "TanLike", "Quotient", "Branch"} <= census
    ours = jax.jit(
        lambda y: graph_coefficients(
            graph, jnp.zeros(2), y.T, leaves, 5, unroll=False, batched_leaves=()
        )
    )(y0s)

    def extended(z):  # time as a third state: the autonomous reference applies
        return jnp.concatenate([_every_rule(z[2], z[:2], None), jnp.ones(1)])

    for member, y0 in enumerate(y0s):
        z0 = jnp.concatenate([y0, jnp.zeros(1)])
        reference = lie_coefficients(extended, z0, 5)[:, :2]
        np.testing.assert_allclose(ours[..., member], reference, rtol=1e-12, atol=1e-13)


def test_a_carried_tape_gives_the_coefficients_of_a_fresh_one():
    # The batch loop hands each step the previous step's tape: whatever it holds
    # (here NaN) must not reach the coefficients, since every row an order reads
    # is written first in the same call.
    y0s = jnp.array([[0.5, 0.1], [2.0, -0.3], [-1.0, 0.7]])
    graph, leaves = lower_vector_field(pendulum, 0.0, y0s[0], 1.5, scalar=True)
    shape = tape_shape(graph, 8, (3,))

    def coefficients(y, **tape):
        return graph_coefficients(
            graph, jnp.zeros(3), y.T, leaves, 8, unroll=False, batched_leaves=(False,),
            **tape,
        )  # fmt: skip

    fresh = jax.jit(coefficients)(y0s)
    carried, tape = jax.jit(coefficients)(y0s, tape=jnp.full(shape, jnp.nan))
    assert tape.shape == shape and jnp.all(jnp.isfinite(fresh))
    np.testing.assert_array_equal(carried, fresh)
    with pytest.raises(ValueError, match="tape_shape"):
        coefficients(y0s, tape=jnp.zeros((shape[0] - 1, shape[1])))


@pytest.fixture(scope="module")
def pendulum_batch():
    y0s = jnp.stack([jnp.linspace(0.2, 2.5, 5), jnp.zeros(5)], axis=1)
    gs = jnp.array([1.0, 2.0, 0.5, 1.5, 3.0])
    ts = jnp.linspace(0.0, 6.0, 4)
    run = jax.jit(
        lambda y0s, gs: taylor_integrate_batch(
            pendulum, y0s, 0.0, 6.0, ts=ts, args=gs, args_axis=0, rtol=1e-13,
            atol=1e-13, tile=2,  # three tiles, the last padded
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
    # more than SMALL_SAVES (the inner saving loop), a grid and an end per member
    t1s = jnp.array([5.0, 3.0])
    ts = jnp.linspace(0.0, 1.0, 41)[None, :] * t1s[:, None]
    y0s = jnp.array([[1.0, 0.0], [0.0, 2.0]])
    run = taylor_integrate_batch(oscillator, y0s, 0.0, t1s, ts=ts)
    assert run.ts.shape == (2, 41)
    exact = jnp.stack(
        [
            jnp.stack([jnp.cos(ts[0]), -jnp.sin(ts[0])], axis=1),
            jnp.stack([2 * jnp.sin(ts[1]), 2 * jnp.cos(ts[1])], axis=1),
        ]
    )
    np.testing.assert_allclose(run.ys, exact, rtol=0, atol=1e-13)


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
