"""Tolerance runs with no solver named pick a method fit for the tolerance, and a
run out of steps is one clear error that keeps what was computed."""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj


def oscillator():
    return lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 - 0.5 * q**2)


def test_tight_tolerance_picks_an_eighth_order_method_and_reaches_it():
    ts = jnp.linspace(0.0, 20.0, 41)
    run = lj.simulate(oscillator(), (1.0, 0.0), t1=20.0, rtol=1e-12, atol=1e-12, ts=ts)
    assert run.stats["solver"] == "Dopri8"
    np.testing.assert_allclose(run.q, np.cos(ts), atol=2e-10)


def test_loose_tolerance_keeps_tsit5():
    run = lj.simulate(oscillator(), (1.0, 0.0), t1=1.0, rtol=1e-6, atol=1e-6)
    assert run.stats["solver"] == "Tsit5"


def test_a_rigid_body_at_tight_tolerance_keeps_its_projection():
    body = lj.RigidBody(jnp.array([1.0, 2.0, 3.0]))
    y0 = (jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([0.1, 1.0, 0.1]))
    run = lj.simulate(body, y0, t1=5.0, rtol=1e-12, atol=1e-12)
    assert run.stats["solver"] == "Dopri8"
    # projected after every step: a unit quaternion to round-off
    assert abs(float(jnp.linalg.norm(run.q[-1])) - 1.0) < 1e-13


def test_out_of_steps_names_max_steps_and_keeps_the_states():
    with pytest.raises(lj.SimulationError, match="max_steps = 20") as caught:
        lj.simulate(oscillator(), (1.0, 0.0), t1=100.0, rtol=1e-12, atol=1e-12,
                    max_steps=20, ts=jnp.linspace(0.0, 100.0, 101))  # fmt: skip
    partial = caught.value.trajectory
    assert partial.result == diffrax.RESULTS.max_steps_reached
    reached = np.isfinite(np.asarray(partial.ts))
    assert 0 < reached.sum() < 101
    np.testing.assert_allclose(
        partial.q[reached], np.cos(np.asarray(partial.ts)[reached]), atol=1e-9
    )


def test_low_order_solver_at_tight_tolerance_is_told_to_use_a_higher_order():
    with pytest.raises(lj.SimulationError, match="Dopri8"):
        lj.simulate(oscillator(), (1.0, 0.0), t1=100.0, rtol=1e-13, atol=1e-13,
                    solver=diffrax.Tsit5(), max_steps=50)  # fmt: skip


def test_a_tolerance_given_to_a_scene_asks_for_a_tolerance_run():
    # A scene's default run steps by its default_dt; a tolerance given with no
    # solver must control the error instead of tuning only the stage solves.
    pendulum = lj.scenes.HarmonicOscillator()  # a separable H: Yoshida4 by default
    y0 = pendulum.initial_state()
    default = lj.simulate(pendulum, y0, t1=5.0)
    tolerance = lj.simulate(pendulum, y0, t1=5.0, rtol=1e-12, atol=1e-12)
    assert tolerance.stats["solver"] == "Dopri8"
    assert default.stats["solver"] != "Dopri8"  # its fixed-step default
    q_exact, _ = pendulum.exact_solution(jnp.asarray(5.0))
    np.testing.assert_allclose(tolerance.q[-1], q_exact, atol=1e-10)
