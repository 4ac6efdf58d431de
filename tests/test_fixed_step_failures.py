"""A failed fixed-step run keeps what it computed, says where it stopped, and why.

Störmer–Verlet is stable only for ωh < 2 (HLW §I.5): on q̈ = −ω²q with ω = 100 and
h = 0.03 (ωh = 3) each step multiplies the state by ≈ 8.9, so it overflows to inf
within a few hundred steps.
"""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._integrate.fixed_step_loop import integrate_every_step

STIFF = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 5e3 * q**2)
START = (jnp.asarray(1.0), jnp.asarray(0.0))
UNSTABLE = dict(t1=100.0, dt=0.03, solver=lj.StormerVerlet())


def test_blow_up_raises_by_default():
    with pytest.raises(Exception, match="non-finite"):
        lj.simulate(STIFF, START, **UNSTABLE)


def test_blow_up_with_throw_false_returns_the_last_finite_state():
    run = lj.simulate(STIFF, START, throw=False, **UNSTABLE)
    assert run.result == diffrax.RESULTS.nonfinite
    assert not bool(run.stats["finite"])
    stopped = float(run.ts[0])
    steps = int(run.stats["num_steps"])
    assert 0.0 < stopped < 100.0
    assert stopped == pytest.approx(steps * 0.03, rel=1e-12)
    assert np.all(np.isfinite(np.asarray(run.q))) and abs(float(run.q[0])) > 1e100


def test_blow_up_while_saving_keeps_the_saves_before_it():
    ts = jnp.linspace(0.0, 90.0, 31)  # every 100 steps
    run = lj.simulate(STIFF, START, ts=ts, throw=False, **UNSTABLE)
    assert run.result == diffrax.RESULTS.nonfinite
    kept = np.isfinite(np.asarray(run.ts))
    assert kept[0] and not kept[-1]
    np.testing.assert_array_equal(np.asarray(run.ts)[kept], np.asarray(ts)[kept])
    assert np.all(np.isfinite(np.asarray(run.q)[kept]))
    assert np.all(np.isinf(np.asarray(run.q)[~kept]))


def test_failed_implicit_solve_returns_the_state_before_it():
    # One stage iteration cannot converge on this stiff step: the first step fails.
    solver = lj.GaussLegendre(stages=2, root_find_max_steps=1)
    run = lj.simulate(STIFF, START, t1=1.0, dt=0.1, solver=solver, throw=False)
    assert run.result != diffrax.RESULTS.successful
    assert float(run.ts[0]) < 1.0
    assert int(run.stats["num_steps"]) == round(float(run.ts[0]) / 0.1)
    assert np.isfinite(float(run.q[0]))


def test_finite_blow_up_of_a_conservative_run_is_a_divergence():
    # 300 unstable steps: energy ≈ 1e20 against 5e3, every number still finite.
    short = dict(UNSTABLE, t1=9.0)
    with pytest.raises(Exception, match="diverged"):
        lj.simulate(STIFF, START, **short)
    run = lj.simulate(STIFF, START, throw=False, **short)
    assert bool(run.stats["finite"])
    assert run.result == diffrax.RESULTS.nonlinear_divergence
    assert float(run.stats["energy_drift"]) > 1e10


def test_stable_runs_and_driven_systems_are_not_judged_diverged():
    stable = lj.simulate(STIFF, START, t1=9.0, dt=0.001, solver=lj.StormerVerlet())
    assert stable.result == diffrax.RESULTS.successful
    # Störmer–Verlet's energy error on the oscillator is of order (ωh)²/4 = 2.5e-3.
    assert 1e-4 < float(stable.stats["energy_drift"]) < 2.5e-3
    # A driven oscillator at resonance gains energy without bound: not judged.
    driven = lj.Lagrangian(
        lambda q, qdot, t: 0.5 * qdot**2 - 0.5 * q**2 + 10.0 * q * jnp.sin(t)
    )
    run = lj.simulate(driven, (0.0, 0.0), t1=200.0, dt=0.01)
    assert run.result == diffrax.RESULTS.successful
    assert np.isnan(float(run.stats["energy_drift"]))
    # Dissipation: the energy falls, and is not judged either.
    damped = lj.Lagrangian(
        lambda q, qdot: 0.5 * qdot**2 - 0.5 * q**2, dissipation=lambda qd: qd**2
    )
    assert np.isnan(
        float(lj.simulate(damped, (1.0, 0.0), t1=5.0, dt=0.01).stats["energy_drift"])
    )


@pytest.mark.parametrize("amplitude", [1.0, 1e10])
def test_last_good_state_is_the_state_of_a_run_that_stops_there(amplitude):
    # The loop takes every step and keeps the last good state beside the running
    # one, two steps per loop trip for Störmer–Verlet; h = 1/32 makes every grid time
    # exact. The two amplitudes overflow after 344 and 333 steps: both parities.
    unstable = dict(t1=100.0, dt=1 / 32, solver=lj.StormerVerlet())
    start = (jnp.asarray(amplitude), jnp.asarray(0.0))
    failed = lj.simulate(STIFF, start, throw=False, **unstable)
    steps = int(failed.stats["num_steps"])
    assert failed.result == diffrax.RESULTS.nonfinite
    # Finite, but judged diverged (its energy is ~1e300): not thrown, compared.
    stopped = lj.simulate(STIFF, start, throw=False, **dict(unstable, t1=steps / 32))
    assert stopped.result == diffrax.RESULTS.nonlinear_divergence
    assert int(stopped.stats["num_steps"]) == steps
    np.testing.assert_array_equal(np.asarray(failed.ys), np.asarray(stopped.ys))
    np.testing.assert_array_equal(np.asarray(failed.ts), np.asarray(stopped.ts))


def test_every_step_outputs_repeat_the_last_good_state_after_a_failure():
    # SaveAt(steps=True)'s loop emits the running state; from the failing step on
    # the entries are the last good state (what `steps_taken` counts up to).
    terms = (
        diffrax.ODETerm(lambda t, p, args: p),
        diffrax.ODETerm(lambda t, q, args: -1e4 * q),
    )
    y0 = (jnp.asarray(1.0), jnp.asarray(0.0))
    last, (qs, ps), _, result, taken = integrate_every_step(
        terms, lj.StormerVerlet(), 0.0, 20.0, 1 / 32, y0, None
    )
    taken = int(taken)
    assert result == diffrax.RESULTS.nonfinite and 0 < taken < 640
    qs, ps = np.asarray(qs), np.asarray(ps)
    assert np.all(np.isfinite(qs)) and np.all(np.isfinite(ps))
    np.testing.assert_array_equal(qs[taken - 1 :], float(last[0]))
    np.testing.assert_array_equal(ps[taken - 1 :], float(last[1]))
    assert qs[taken - 2] != qs[taken - 1]
