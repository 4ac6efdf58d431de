"""diffrax options through `simulate`: step-size controllers, progress meters, and the
defaults a scene supplies."""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._integrate.solver_choice import default_solver
from lagjax.scenes.central import KeplerCartesian
from lagjax.scenes.pendulums import SimplePendulum

OSCILLATOR = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 0.5 * q**2)


def test_step_to_controller_steps_on_its_grid():
    """StepTo on a uniform grid is the fixed-step run of that step, to round-off."""
    grid = jnp.linspace(0.0, 2.0, 21)
    stepped = lj.simulate(
        OSCILLATOR, (1.0, 0.0), t1=2.0, solver=lj.Yoshida4(),
        stepsize_controller=diffrax.StepTo(ts=grid),
    )  # fmt: skip
    fixed = lj.simulate(OSCILLATOR, (1.0, 0.0), t1=2.0, dt=0.1, solver=lj.Yoshida4())
    assert int(stepped.stats["num_steps"]) == 20
    assert np.allclose(stepped.q, fixed.q, rtol=0, atol=1e-14)
    assert np.allclose(stepped.p, fixed.p, rtol=0, atol=1e-14)


def test_pid_controller_sets_the_accuracy():
    """The caller's PID tolerances, not rtol/atol, decide the error: q = cos t."""
    errors = []
    for tolerance in (1e-6, 1e-11):
        run = lj.simulate(
            OSCILLATOR, (1.0, 0.0), t1=5.0, solver=diffrax.Tsit5(),
            stepsize_controller=diffrax.PIDController(rtol=tolerance, atol=tolerance),
        )  # fmt: skip
        errors.append(abs(float(run.q[-1]) - np.cos(5.0)))
    assert errors[1] < 1e-9 < errors[0]


def test_adaptive_controller_needs_an_error_estimate():
    with pytest.raises(ValueError, match="makes none"):
        lj.simulate(
            OSCILLATOR, (1.0, 0.0), t1=1.0, solver=lj.StormerVerlet(),
            stepsize_controller=diffrax.PIDController(rtol=1e-6, atol=1e-6),
        )  # fmt: skip


def test_step_to_refuses_a_dt_and_controllers_must_be_controllers():
    with pytest.raises(ValueError, match="leave dt unset"):
        lj.simulate(
            OSCILLATOR, (1.0, 0.0), t1=1.0, dt=0.1, solver=lj.StormerVerlet(),
            stepsize_controller=diffrax.StepTo(ts=jnp.linspace(0.0, 1.0, 5)),
        )  # fmt: skip
    with pytest.raises(TypeError, match="step-size controller"):
        lj.simulate(OSCILLATOR, (1.0, 0.0), t1=1.0, stepsize_controller=1e-6)


def test_progress_meter_is_passed_through(capfd):
    lj.simulate(
        OSCILLATOR, (1.0, 0.0), t1=1.0, dt=0.1, solver=lj.StormerVerlet(),
        progress_meter=diffrax.TextProgressMeter(),
    )  # fmt: skip
    assert "100.00%" in capfd.readouterr().out
    with pytest.raises(ValueError, match="not both"):
        lj.simulate(
            OSCILLATOR, (1.0, 0.0), progress=True,
            progress_meter=diffrax.TextProgressMeter(),
        )  # fmt: skip


def test_a_scene_supplies_its_span_step_and_solver():
    scene = KeplerCartesian()
    run = lj.simulate(scene, scene.initial_state())
    steps = round(scene.default_t1 / scene.default_dt)
    assert float(run.ts[-1]) == pytest.approx(scene.default_t1, rel=1e-14)
    assert int(run.stats["num_steps"]) == steps
    assert run.stats["solver"] == type(default_solver(scene, scene.default_dt)).__name__
    # One period later the orbit is back at periapsis (Kepler's third law: T = 2π).
    start_q, _ = scene.initial_state()
    assert np.allclose(run.q[-1], start_q, atol=1e-6)


def test_plain_systems_keep_t1_10_and_adaptive_stepping():
    run = lj.simulate(OSCILLATOR, (1.0, 0.0))
    assert float(run.ts[-1]) == 10.0
    assert run.stats["solver"] not in ("StormerVerlet", "Yoshida4")
    assert int(run.stats["num_steps"]) > 0


def test_checks_refuse_a_trajectory_they_cannot_judge():
    """The pendulum's period comes from zero crossings among the saves: a run that
    saved only its final state is refused, not answered with NaN."""
    scene = SimplePendulum()
    final_only = lj.simulate(scene, scene.initial_state())
    with pytest.raises(ValueError, match="cannot judge this trajectory"):
        scene.checks(final_only)
