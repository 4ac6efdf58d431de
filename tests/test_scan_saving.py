"""Fixed-step runs saving off the grid, every step, or densely, run as scans.

Oracles: the harmonic oscillator's exact solution q = cos t (and its derivative in
q0, which is q itself: the flow is linear), the method's order between steps, and
diffeqsolve's general loop on the same solver (forced by
`stepsize_controller=diffrax.ConstantStepSize()`), which must agree to round-off
on a span that is a whole number of steps.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._integrate.scan_saving import scan_saving

OSCILLATOR = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 0.5 * q**2)
START = (jnp.asarray(1.0), jnp.asarray(0.0))
DIFFRAX_LOOP = dict(stepsize_controller=diffrax.ConstantStepSize())
# NumPy, like the other times below: arithmetic on them then compiles nothing.
OFF_GRID = np.array([0.0, 0.123, 0.5, 0.5, 0.5001, 0.77, 1.3, 2.0])


@eqx.filter_jit
def evaluate(run, times):
    """`run.evaluate(times)` compiled whole: eagerly, its range checks and the
    lookup of the step would each dispatch (and compile) op by op."""
    return run.evaluate(times)


def assert_same_run(scan, loop, atol):
    """Same times (inf where unused) and states, to `atol`."""
    ts_scan, ts_loop = np.asarray(scan.ts), np.asarray(loop.ts)
    assert ts_scan.shape == ts_loop.shape
    used = np.isfinite(ts_loop)
    np.testing.assert_array_equal(np.isfinite(ts_scan), used)
    np.testing.assert_allclose(ts_scan[used], ts_loop[used], rtol=0, atol=1e-15)
    for a, b in zip(scan.ys, loop.ys):
        a, b = np.asarray(a), np.asarray(b)
        np.testing.assert_allclose(a[used], b[used], rtol=0, atol=atol)
        assert np.all(np.isinf(a[~used]))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "system, solver",
    [
        (OSCILLATOR, lj.Yoshida6()),  # quintic Hermite (the cubic: below)
        (OSCILLATOR, diffrax.Tsit5()),  # the solver's own extension
    ],
)
def test_off_grid_saves_equal_the_diffrax_loop(system, solver):
    options = dict(t1=2.0, dt=0.01, solver=solver, ts=OFF_GRID)
    scan = lj.simulate(system, START, **options)
    loop = lj.simulate(system, START, **options, **DIFFRAX_LOOP)
    assert_same_run(scan, loop, atol=1e-14)


def test_off_grid_saves_keep_the_order_between_steps():
    """Yoshida4 with its cubic extension: fourth order at times off the grid, on
    the exact solution."""
    times = np.linspace(0.0137, 9.9, 57)  # spaced 0.1737: never on a grid point
    errors = []
    for dt in (0.1, 0.05):
        run = lj.simulate(OSCILLATOR, START, t1=10.0, dt=dt, ts=times)
        errors.append(float(np.max(np.abs(np.asarray(run.q) - np.cos(times)))))
    assert errors[1] < 1e-5
    assert 3.6 < np.log2(errors[0] / errors[1]) < 4.4


def test_backward_off_grid_saves_and_dense_output_follow_the_solution():
    times = -OFF_GRID
    run = lj.simulate(
        OSCILLATOR, START, t1=-2.0, dt=-0.01, solver=lj.Yoshida6(), ts=times,
        dense=True,
    )  # fmt: skip
    np.testing.assert_allclose(run.q, np.cos(times), rtol=0, atol=1e-12)
    q, p = evaluate(run, np.linspace(0.0, -2.0, 33))
    np.testing.assert_allclose(q, np.cos(np.linspace(0.0, 2.0, 33)), atol=1e-12)
    np.testing.assert_allclose(p, np.sin(np.linspace(0.0, 2.0, 33)), atol=1e-12)


@pytest.mark.parametrize(
    "saveat",
    [
        diffrax.SaveAt(steps=True),
        diffrax.SaveAt(t0=True, steps=3, t1=True),  # 100 steps: t1 is no third
    ],
)
def test_step_saves_have_the_diffrax_layout(saveat):
    options = dict(t1=1.0, dt=0.01, solver=lj.Yoshida4(), saveat=saveat)
    scan = lj.simulate(OSCILLATOR, START, **options)
    loop = lj.simulate(OSCILLATOR, START, **options, **DIFFRAX_LOOP)
    assert_same_run(scan, loop, atol=1e-14)
    used = np.isfinite(np.asarray(scan.ts))
    np.testing.assert_allclose(
        np.asarray(scan.q)[used], np.cos(np.asarray(scan.ts)[used]), atol=1e-9
    )


def test_dense_output_equals_the_diffrax_loop():
    options = dict(t1=2.0, dt=0.05, solver=lj.Yoshida4(), dense=True)
    scan = lj.simulate(OSCILLATOR, START, **options)
    loop = lj.simulate(OSCILLATOR, START, **options, **DIFFRAX_LOOP)
    times = np.linspace(0.0, 2.0, 41) + 0.013 * np.sin(np.arange(41.0))
    times = np.clip(times, 0.0, 2.0)
    on_scan = evaluate(scan, times)
    for a, b in zip(on_scan, evaluate(loop, times)):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-14)
    # Energy between the steps: conserved to the extension's order, 4.
    q, p = map(np.asarray, on_scan)
    assert float(np.max(np.abs(0.5 * (q**2 + p**2) - 0.5))) < 1e-5


def test_reverse_mode_through_off_grid_saves():
    """q(t) is linear in q0 with p0 = 0: ∂q(t)/∂q0 = cos t."""

    def saved_positions(q0):
        options = dict(t1=2.0, dt=0.01, solver=lj.Yoshida4(), ts=OFF_GRID)
        return lj.simulate(OSCILLATOR, (q0, 0.0), **options).q

    jacobian = jax.jacrev(saved_positions)(1.0)
    np.testing.assert_allclose(jacobian, np.cos(OFF_GRID), atol=1e-8)


def test_a_failure_keeps_the_saves_before_it():
    """Störmer–Verlet with ωh = 3 > 2 overflows (test_fixed_step_failures)."""
    stiff = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 5e3 * q**2)
    options = dict(t1=100.0, dt=0.03, solver=lj.StormerVerlet(), throw=False)
    off_grid = lj.simulate(stiff, START, ts=jnp.linspace(0.01, 99.0, 50), **options)
    steps = lj.simulate(stiff, START, saveat=diffrax.SaveAt(steps=True), **options)
    final = lj.simulate(stiff, START, **options)
    for run in (off_grid, steps):
        assert run.result == diffrax.RESULTS.nonfinite
        kept = np.isfinite(np.asarray(run.ts))
        assert 0 < kept.sum() < kept.size
        assert not kept[np.argmin(kept) :].any()  # the saves before the failure
        assert np.all(np.isfinite(np.asarray(run.q)[kept]))
        # Every path stops at the same step: the last one before the overflow.
        assert int(run.stats["num_steps"]) == int(final.stats["num_steps"]) > 0


def test_which_requests_the_scan_takes():
    def plan(ts=None, saveat=None, dense=False, max_steps=None):
        return scan_saving(0.0, 1.0, 0.01, ts, saveat, dense, max_steps, jnp.float64)

    assert plan(ts=np.array([0.05, 0.555])) is not None
    assert plan(saveat=diffrax.SaveAt(steps=True)) is not None
    assert plan(dense=True) is not None
    # Left to diffeqsolve: max_steps too small for the run, SaveAt(fn=...),
    # SaveAt(ts=...), and save times bunched apart (most steps would be wasted).
    assert plan(dense=True, max_steps=50) is None
    assert plan(saveat=diffrax.SaveAt(t1=True, fn=lambda t, y, args: y[0])) is None
    assert plan(saveat=diffrax.SaveAt(ts=np.array([0.5]))) is None
    bunched = np.concatenate([np.linspace(0.0, 0.01, 30), [1.0]])
    assert plan(ts=bunched) is None
