"""`lj.Taylor(backend="heyoka")` under JAX transformations: `jax.vmap` over y0 and
args (and `lj.sweep`, `run_taylor_batch`) reaches heyoka's batch mode in one call
and equals the single runs; `jax.jit` runs it through a callback; `jax.grad` is
refused by name."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj

pytest.importorskip("heyoka")

from lagjax._integrate.taylor_batch import run_taylor_batch
from lagjax.taylor import heyoka_runs
from lagjax.taylor.heyoka_cache import translated

HEYOKA = lj.Taylor(backend="heyoka", rtol=1e-15, atol=1e-15)
AMPLITUDES = jnp.linspace(0.2, 2.0, 6)  # not a multiple of the SIMD width


def pendulum(q, qdot, t, args):
    return 0.5 * qdot**2 + args["g"] * jnp.cos(q)


PENDULUM = lj.Lagrangian(pendulum)
G = {"g": jnp.asarray(9.81)}


def final_angle(theta0, args=G):
    run = lj.simulate(PENDULUM, (theta0, 0.0), t1=2.0, args=args, solver=HEYOKA)
    return run.q[-1]


@pytest.fixture
def batches(monkeypatch):
    """The batch sizes each run of heyoka was handed."""
    sizes = []
    call = heyoka_runs.HeyokaRunner.__call__

    def recording(self, y0s, *rest):
        sizes.append(len(y0s))
        return call(self, y0s, *rest)

    monkeypatch.setattr(heyoka_runs.HeyokaRunner, "__call__", recording)
    return sizes


@pytest.mark.integration  # compiles heyoka's batch integrator and its scalar one
def test_vmap_over_y0_is_one_batch_equal_to_single_runs(batches):
    batched = jax.vmap(final_angle)(AMPLITUDES)
    assert batches == [AMPLITUDES.size]
    singles = [final_angle(float(a)) for a in AMPLITUDES]
    # SIMD and scalar code round the elementary functions differently
    np.testing.assert_allclose(batched, singles, rtol=0, atol=1e-13)


def test_jit_of_vmap_over_args_equals_single_runs(batches):
    gs = jnp.linspace(1.0, 20.0, 5)
    batched = jax.jit(jax.vmap(lambda g: final_angle(1.0, {"g": g})))(gs)
    assert batches == [gs.size]
    singles = [final_angle(1.0, {"g": float(g)}) for g in gs]
    np.testing.assert_allclose(batched, singles, rtol=0, atol=1e-13)


def test_jit_of_one_run_equals_the_direct_run():
    jitted = jax.jit(final_angle)(jnp.asarray(0.7))
    assert jitted == pytest.approx(float(final_angle(0.7)), abs=1e-15)


def test_one_member_to_its_end_equals_the_batch_path(batches):
    """One member under `jit` (no `vmap`) runs straight to t1
    (`HeyokaRunner.one_to_end`, no batch bookkeeping): the batch path's rows,
    bit for bit, and its refusal of NaN or unordered times."""
    jitted = jax.jit(final_angle)(jnp.asarray(0.7))
    assert batches == []  # the runner's batch call was not needed
    assert float(jitted) == float(final_angle(0.7))

    def field(t, y, args):
        return jnp.stack([y[1], -args["g"] * jnp.sin(y[0])])

    runner = heyoka_runs.HeyokaRunner(translated(field, 2, G), 1e-15, 10_000)
    y0, pars = np.array([0.7, 0.0]), np.array([9.81])
    for t0, t1, ts in ((0.0, 2.0, [2.0]), (0.0, np.nan, [np.nan]),
                       (2.0, -1.0, [-1.0]), (0.0, 2.0, [3.0])):  # fmt: skip
        one = runner.one_to_end(y0, pars, t0, t1, np.array(ts))
        rows = heyoka_runs.HeyokaRunner.__call__(
            runner, y0[None], pars[None], np.array([t0]), np.array([t1]),
            np.array([ts]),
        )  # fmt: skip
        assert one is not None
        for got, want in zip(one, rows):
            np.testing.assert_array_equal(got, want[0])


def test_gradients_are_refused_by_name():
    with pytest.raises(TypeError, match=r"backend='jax'"):
        jax.grad(final_angle)(0.7)
    with pytest.raises(TypeError, match=r"cannot be differentiated"):
        jax.jvp(final_angle, (0.7,), (1.0,))


@pytest.mark.integration
def test_run_taylor_batch_has_a_leading_batch_axis():
    y0s = (AMPLITUDES, jnp.zeros_like(AMPLITUDES))
    batch = run_taylor_batch(PENDULUM, y0s, None, 0.0, 2.0, jnp.linspace(0, 2, 3),
                             HEYOKA, 1e-15, 1e-15, None, True, args=G)  # fmt: skip
    assert batch.q.shape == (AMPLITUDES.size, 3) and batch.ts.shape == (6, 3)
    assert np.all(batch.stats["succeeded"])
    assert np.all(batch.result == diffrax.RESULTS.successful)
    np.testing.assert_allclose(batch.q[:, -1], jax.vmap(final_angle)(AMPLITUDES),
                               rtol=0, atol=1e-13)  # fmt: skip


def test_a_failed_member_is_told_by_its_result():
    """Under `jit` (as `lj.sweep` runs it): one XLA compilation, where the eager
    `vmap` of the test above compiles each operation of the run."""
    y0s = (AMPLITUDES, jnp.zeros_like(AMPLITUDES))
    few = lj.Taylor(backend="heyoka", rtol=1e-15, atol=1e-15, max_steps=3)
    batch = jax.jit(lambda y0s: run_taylor_batch(PENDULUM, y0s, None, 0.0, 2.0,
                                                 None, few, 1e-15, 1e-15, 3, False,
                                                 args=G))(y0s)  # fmt: skip
    assert not np.any(batch.stats["succeeded"])
    assert np.all(batch.result == diffrax.RESULTS.max_steps_reached)


@pytest.mark.integration  # compiles lj.sweep's sharded program
def test_sweep_is_one_batch_equal_to_single_runs(batches):
    gs = jnp.linspace(1.0, 20.0, 5)
    swept = lj.sweep(PENDULUM, (jnp.full(5, 1.0), jnp.zeros(5)), {"g": gs},
                     t1=2.0, solver=HEYOKA)  # fmt: skip
    assert batches == [gs.size]
    singles = [final_angle(1.0, {"g": float(g)}) for g in gs]
    np.testing.assert_allclose(swept.q[:, -1], singles, rtol=0, atol=1e-13)
