"""`jax.vmap(simulate(..., solver=lj.Taylor()))` runs the batch-native loop
(`lagjax.taylor.vmap_rule`): the same steps and states as the batch loop and the
batched one-trajectory loop, closed forms and conserved energies per member,
derivatives through a vmapped run against finite differences, and the tile
chosen by the platform."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
import lagjax.taylor.vmap_rule as vmap_rule
from lagjax.taylor import taylor_integrate
from lagjax.taylor.batch import (
    ACCELERATOR_TILE,
    CPU_TILE,
    default_tile,
    taylor_integrate_batch,
)

TOLERANCE = 1e-13


def pendulum(q, qdot, t, args):
    return 0.5 * qdot**2 + args["g"] * jnp.cos(q)


def pendulum_field(t, y, g):
    return jnp.stack([y[1], -g * jnp.sin(y[0])])


@pytest.fixture
def batch_calls(monkeypatch):
    """The batch sizes `jax.vmap` of a Taylor run handed to the batch loop."""
    calls = []

    def spy(vector_field, y0s, *args, **kwargs):
        calls.append(y0s.shape[0])
        return taylor_integrate_batch(vector_field, y0s, *args, **kwargs)

    monkeypatch.setattr(vmap_rule, "taylor_integrate_batch", spy)
    return calls


def test_default_tile_follows_the_platform():
    assert default_tile("cpu", 10**6) == CPU_TILE == 32
    for platform in ("gpu", "cuda", "rocm", "tpu"):
        assert default_tile(platform, 10**4) == 10**4  # the whole batch
        assert default_tile(platform, 7) == 7
        # beyond the cap: equal tiles, none above it, padding under one per tile
        members = 10**6
        tile = default_tile(platform, members)
        count = -(-members // tile)
        assert tile <= ACCELERATOR_TILE
        assert count * tile - members < count


def test_a_bad_tile_is_refused_by_name():
    with pytest.raises(ValueError, match="tile"):
        lj.Taylor(tile=0)
    with pytest.raises(ValueError, match="tile"):
        taylor_integrate_batch(
            lambda t, y, args: -y, jnp.ones((2, 1)), 0.0, 1.0, tile=-3
        )


def oscillator_final(omega, t1, solver):
    """The oscillator's angle at t1, its frequency closed over by the Lagrangian."""
    lag = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 - 0.5 * omega**2 * q**2)
    return lj.simulate(lag, (1.0, 0.0), t1=t1, solver=solver)


def test_vmap_over_a_closed_over_frequency_and_end_times_runs_the_batch_loop(
    batch_calls,
):
    solver = lj.Taylor(rtol=TOLERANCE, atol=TOLERANCE)
    omegas, t1s = jnp.array([1.3, 0.7, 2.1]), jnp.array([0.5, 2.0, 7.5])
    runs = jax.vmap(lambda w, t1: oscillator_final(w, t1, solver))(omegas, t1s)
    assert batch_calls == [3]
    np.testing.assert_allclose(runs.ts[:, -1], t1s, rtol=0, atol=0)
    np.testing.assert_allclose(runs.q[:, -1], jnp.cos(omegas * t1s), atol=1e-12)
    steps = np.asarray(runs.stats["num_steps"])
    assert steps[0] < steps[1] < steps[2]  # each member took its own steps


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_the_gradient_through_a_closed_over_frequency_is_the_closed_forms():
    solver = lj.Taylor(rtol=TOLERANCE, atol=TOLERANCE)
    omegas, t1 = jnp.array([0.7, 1.3, 2.1]), 3.0
    slopes = jax.jit(
        jax.vmap(jax.grad(lambda w: oscillator_final(w, t1, solver).q[-1]))
    )(omegas)
    # d cos(ωt)/dω = −t sin(ωt)
    np.testing.assert_allclose(slopes, -t1 * jnp.sin(omegas * t1), rtol=1e-10)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_vmap_of_simulate_equals_the_batch_loop_and_the_batched_single_loop(
    batch_calls,
):
    lag = lj.Lagrangian(pendulum)
    solver = lj.Taylor(rtol=TOLERANCE, atol=TOLERANCE)
    q0s, gs = jnp.linspace(0.2, 2.5, 5), jnp.array([1.0, 2.0, 0.5, 1.5, 3.0])
    ts = jnp.linspace(0.0, 6.0, 4)

    def run(q0, g):
        return lj.simulate(lag, (q0, 0.0), t1=6.0, ts=ts, args={"g": g}, solver=solver)

    swept = jax.jit(jax.vmap(run))(q0s, gs)
    assert batch_calls == [5]
    y0s = jnp.stack([q0s, jnp.zeros(5)], axis=1)
    options = dict(ts=ts, rtol=TOLERANCE, atol=TOLERANCE)
    batch = jax.jit(
        lambda y0s, gs: taylor_integrate_batch(
            pendulum_field, y0s, 0.0, 6.0, args=gs, args_axis=0, **options
        )
    )(y0s, gs)
    single = jax.jit(
        jax.vmap(
            lambda y0, g: taylor_integrate(
                pendulum_field, y0, 0.0, 6.0, args=g, **options
            )
        )
    )(y0s, gs)
    for reference in (batch, single):
        np.testing.assert_array_equal(swept.stats["num_steps"], reference.num_steps)
        np.testing.assert_allclose(swept.q, reference.ys[..., 0], rtol=0, atol=1e-13)
        np.testing.assert_allclose(swept.qdot, reference.ys[..., 1], rtol=0, atol=1e-13)
    energy = swept.energy()
    assert float(jnp.max(jnp.abs(energy - energy[:, :1]))) < 1e-12


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_gradients_through_a_vmapped_run_match_finite_differences():
    lag = lj.Lagrangian(pendulum)
    q0s, gs = jnp.linspace(0.2, 2.5, 5), jnp.array([1.0, 2.0, 0.5, 1.5, 3.0])

    def finals(q0s, gs, solver):
        run = lambda q0, g: lj.simulate(
            lag, (q0, 0.0), t1=3.0, args={"g": g}, solver=solver
        ).q[-1]
        return jax.vmap(run)(q0s, gs)

    reverse = lj.Taylor(rtol=TOLERANCE, atol=TOLERANCE)
    forward = lj.Taylor(rtol=TOLERANCE, atol=TOLERANCE, forward_mode=True)
    loss = lambda q0s, gs: jnp.sum(finals(q0s, gs, reverse) ** 2)
    grad_q0, grad_g = jax.jit(jax.grad(loss, argnums=(0, 1)))(q0s, gs)
    _, tangent = jax.jit(
        lambda gs: jax.jvp(lambda gs: finals(q0s, gs, forward), (gs,), (jnp.ones(5),))
    )(gs)
    eps = 1e-6
    central = jax.jit(
        lambda dq, dg: (finals(q0s + dq, gs + dg, reverse) - finals(q0s - dq, gs - dg, reverse))
        / (2 * eps)
    )  # fmt: skip
    zeros, eye = jnp.zeros(5), eps * jnp.eye(5)
    # each member's final angle depends on its own g only: d(sum θ²)/dg_i = 2θ_i ∂θ_i/∂g_i
    theta = finals(q0s, gs, reverse)
    by_member_g = jnp.stack([central(zeros, eye[i])[i] for i in range(5)])
    by_member_q = jnp.stack([central(eye[i], zeros)[i] for i in range(5)])
    np.testing.assert_allclose(grad_g, 2 * theta * by_member_g, rtol=1e-6)
    np.testing.assert_allclose(grad_q0, 2 * theta * by_member_q, rtol=1e-6)
    np.testing.assert_allclose(tangent, by_member_g, rtol=1e-6)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_batched_tolerances_run_each_member_at_its_own(batch_calls):
    lag = lj.Lagrangian(pendulum)
    rtols = jnp.array([1e-9, 1e-13])

    def run(rtol):
        solver = lj.Taylor(rtol=rtol, atol=1e-13, order=14)
        return lj.simulate(lag, (1.0, 0.0), t1=5.0, args={"g": 1.0}, solver=solver)

    runs = jax.jit(jax.vmap(run))(rtols)
    assert batch_calls == []  # the batch loop takes one tolerance: vmap of the run
    alone = [run(float(rtol)) for rtol in rtols]
    for member, one in enumerate(alone):
        assert int(runs.stats["num_steps"][member]) == int(one.stats["num_steps"])
        np.testing.assert_allclose(runs.q[member], one.q, rtol=0, atol=1e-14)
    steps = np.asarray(runs.stats["num_steps"])
    assert steps[0] < steps[1]  # a looser tolerance, longer steps
