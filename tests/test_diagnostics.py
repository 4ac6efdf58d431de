"""The measurement helpers of `lagjax.diagnostics`, judged against physics.

The oracle is the large-amplitude pendulum: after one exact period (the AGM closed
form) it is back where it started, so the final-state error of a run of one period
is the method's global error, and its slope against the step is the method's order
(2 for Störmer–Verlet, 4 for Yoshida's triple jump). The energy error of a
symplectic method is bounded and shrinks like its order.
"""

import statistics
import time

import diffrax
import jax.numpy as jnp
import matplotlib
import numpy as np
import pytest

import lagjax as lj
from lagjax import diagnostics
from lagjax.scenes.pendulums import SimplePendulum

matplotlib.use("Agg")

PENDULUM = SimplePendulum()  # released at rest from 150°
PERIOD = float(PENDULUM.period())


def one_period(solver, steps: int, saved: int | None = None):
    dt = PERIOD / int(steps)  # a Python float: simulate's static step count
    ts = None if saved is None else diagnostics.sample_times(0.0, PERIOD, saved, dt)
    return lj.simulate(
        PENDULUM,
        PENDULUM.initial_state(),
        t1=PERIOD,
        dt=dt,
        solver=solver,
        ts=ts,
        max_steps=None if saved is None else int(steps) + 2,
    )


START = (PENDULUM.amplitude, jnp.asarray(0.0))  # (θ, θ̇) after a whole period


@pytest.mark.parametrize(
    "solver, order", [(lj.StormerVerlet(), 2), (lj.Yoshida4(), 4)], ids=["SV", "Y4"]
)
def test_final_state_error_converges_at_the_method_order(solver, order):
    steps = np.array([100, 200, 400, 800])
    errors = [
        diagnostics.final_state_error(one_period(solver, n), START) for n in steps
    ]
    assert np.all(np.diff(errors) < 0), errors
    assert errors[-1] > 1e-12  # truncation, not round-off, sets the slope
    measured = diagnostics.convergence_order(PERIOD / steps, errors)
    assert abs(measured - order) < 0.2, (measured, errors)


def test_final_state_error_is_relative_and_compares_position_and_velocity():
    trajectory = one_period(lj.StormerVerlet(), 200)
    relative = diagnostics.final_state_error(trajectory, START)
    absolute = diagnostics.final_state_error(trajectory, START, relative=False)
    theta, theta_dot = trajectory.q[-1], trajectory.qdot[-1]
    distance = float(jnp.hypot(theta - START[0], theta_dot - START[1]))
    assert absolute == pytest.approx(distance, rel=1e-12)
    assert relative == pytest.approx(distance / float(PENDULUM.amplitude), rel=1e-12)
    # Trajectory against trajectory: itself is an exact match.
    assert diagnostics.final_state_error(trajectory, trajectory) == 0.0


def test_final_state_error_refuses_mismatched_states():
    with pytest.raises(ValueError, match="components"):
        diagnostics.final_state_error((jnp.zeros(2), jnp.zeros(2)), jnp.zeros(3))


def test_energy_error_of_a_symplectic_method_is_bounded_and_shrinks_like_its_order():
    steps = np.array([100, 200, 400])
    errors = [
        float(diagnostics.energy_error(one_period(lj.StormerVerlet(), n, saved=50)))
        for n in steps
    ]
    measured = diagnostics.convergence_order(PERIOD / steps, errors)
    assert abs(measured - 2) < 0.2, (measured, errors)
    assert 1e-10 < errors[-1] < 1e-2


def test_energy_error_from_energies_reference_and_batch():
    energies = jnp.array([[2.0, 2.2, 1.9], [-1.0, -1.0, -1.5]])
    np.testing.assert_allclose(diagnostics.energy_error(energies), [0.1, 0.5])
    np.testing.assert_allclose(
        diagnostics.energy_error(energies[0], reference=2.2), 0.3 / 2.2
    )
    # E₀ = 0: the absolute deviation, not a division by zero.
    assert float(diagnostics.energy_error(jnp.array([0.0, 1e-3]))) == pytest.approx(
        1e-3
    )
    with pytest.raises(ValueError, match="several"):
        diagnostics.energy_error(jnp.asarray(1.0))


def test_convergence_order_recovers_a_power_law_and_rejects_bad_input():
    dts = np.array([0.1, 0.05, 0.025])
    assert diagnostics.convergence_order(dts, 3.0 * dts**6) == pytest.approx(6.0)
    assert diagnostics.convergence_order(1 / dts, dts**2) == pytest.approx(-2.0)
    with pytest.raises(ValueError):
        diagnostics.convergence_order([0.1], [1e-3])
    with pytest.raises(ValueError):
        diagnostics.convergence_order([0.1, 0.05], [1e-3, 0.0])


def test_time_run_compiles_apart_and_reports_the_median():
    timing = diagnostics.time_run(lambda x: jnp.sin(x) * 2, jnp.ones(3), repeats=4)
    assert timing.compile_seconds > 0
    assert len(timing.runs) == 4
    assert timing.run_seconds == statistics.median(timing.runs)
    np.testing.assert_allclose(timing.output, 2 * np.sin(1.0))


def test_time_run_without_jit_and_with_a_time_budget():
    def slow():
        time.sleep(0.02)
        return 7

    timing = diagnostics.time_run(slow, jit=False, repeats=50, max_seconds=0.05)
    assert timing.compile_seconds == 0.0
    assert 1 <= len(timing.runs) <= 3  # stopped by the budget, not by `repeats`
    assert timing.run_seconds >= 0.02
    assert timing.output == 7


def test_failure_reason_finds_the_line_meant_for_the_user():
    degenerate = lj.Lagrangian(lambda q, qd: 0.5 * (qd[0] + qd[1]) ** 2 - jnp.sum(q**2))
    with pytest.raises(Exception) as raised:
        lj.simulate(
            degenerate,
            (jnp.array([1.0, 0.0]), jnp.zeros(2)),
            t1=1.0,
            dt=0.1,
            solver=diffrax.Tsit5(),
        )
    reason = diagnostics.failure_reason(raised.value)
    assert "non-finite" in reason and "\n" not in reason
    assert (
        diagnostics.failure_reason(ValueError("bad dt\nmore")) == "ValueError: bad dt"
    )


def test_fastest_within_and_median_ratio():
    point = diagnostics.WorkPrecisionPoint
    points = [
        point("a", 1e-2, 1.0, 1e-7),
        point("b", 1e-3, 0.1, 1e-5),
        point("b", 1e-4, 0.3, 1e-8),
        point("c", 1e-4, 0.01, float("nan")),
    ]
    assert diagnostics.fastest_within(points, 1e-4) == points[1]
    assert diagnostics.fastest_within(points, 1e-6) == points[2]
    assert diagnostics.fastest_within(points, 1e-9) is None
    assert diagnostics.median_ratio([2.0, 9.0, 4.0], [1.0, 3.0, 1.0]) == 3.0
    assert np.isnan(diagnostics.median_ratio([1.0], [0.0]))


def test_plot_work_precision_draws_one_line_per_method():
    point = diagnostics.WorkPrecisionPoint
    points = [point("lagjax A", 1, 0.1, 1e-3), point("lagjax A", 2, 0.2, 1e-5)]
    points += [point("peer B", 1, 0.3, 1e-4), point("peer B", 2, 0.5, 1e-6)]
    axes = diagnostics.plot_work_precision(points, title="test")
    assert [line.get_label() for line in axes.get_lines()] == ["lagjax A", "peer B"]
    assert axes.get_xscale() == axes.get_yscale() == "log"
    assert axes.get_title() == "test" and "run time" in axes.get_xlabel()
