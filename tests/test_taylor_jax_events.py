"""Events on the step polynomial with `lj.Taylor(backend="jax")`: event times
against closed forms (the pendulum's quarter period, a projectile's flight, a
Kepler orbit's pericentre passage from Kepler's equation), the derivative of an
event time, and agreement with heyoka's route."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.special_functions import complete_elliptic_k_from_complement

TAYLOR = lj.Taylor(rtol=1e-15, atol=1e-15)
PENDULUM = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))
CROSSES_ZERO = diffrax.Event(lambda t, y, args: y[0])


def quarter_period(theta0):
    """K(m), m = sin²(θ₀/2), for ω₀ = 1; from the complement cos²(θ₀/2), which
    keeps its digits at large amplitude."""
    return complete_elliptic_k_from_complement(jnp.cos(theta0 / 2) ** 2)


def time_to_bottom(theta0):
    run = lj.simulate(PENDULUM, (theta0, 0.0), t1=20.0, solver=TAYLOR,
                      event=CROSSES_ZERO)  # fmt: skip
    return run.ts[0], run.q[0], run.qdot[0], run.stats["event_mask"]


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_the_pendulum_reaches_the_bottom_after_a_quarter_period_under_jit():
    amplitudes = jnp.array([0.5, 2.0, 3.0])
    times, q, qdot, fired = jax.jit(jax.vmap(time_to_bottom))(amplitudes)
    np.testing.assert_allclose(times, quarter_period(amplitudes), rtol=1e-14)
    assert np.all(fired)
    assert np.all(np.abs(q) < 1e-14)  # the saved state is the one at the event
    energy = 1 - np.cos(amplitudes)  # all kinetic at the bottom
    np.testing.assert_allclose(qdot, -np.sqrt(2 * energy), rtol=1e-13)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_the_event_time_is_differentiable():
    slope = jax.grad(lambda theta0: time_to_bottom(theta0)[0])(2.0)
    assert float(slope) == pytest.approx(
        float(jax.grad(quarter_period)(2.0)), rel=1e-10
    )


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_a_projectile_lands_at_2v_over_g_inside_one_long_step():
    projectile = lj.Lagrangian(lambda q, v: 0.5 * jnp.sum(v**2) - 9.81 * q[1])
    lands = diffrax.Event(lambda t, y, args: y[0][1], direction=False)
    y0 = (jnp.zeros(2), jnp.array([3.0, 4.0]))  # the condition is 0 at t0
    # The solution is a polynomial: the first step spans the whole run, and the
    # landing lies in its first sample interval (the start's zero is no event).
    run = lj.simulate(projectile, y0, t1=1000.0, solver=TAYLOR, event=lands)
    flight = 2 * 4.0 / 9.81
    assert run.result == diffrax.RESULTS.event_occurred
    assert int(run.stats["num_steps"]) == 1
    assert run.ts[0] == pytest.approx(flight, rel=1e-14)
    np.testing.assert_allclose(run.q[0], [3.0 * flight, 0.0], atol=1e-13)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_a_kepler_orbit_passes_pericentre_when_keplers_equation_says():
    kepler = lj.Hamiltonian(
        lambda q, p: 0.5 * jnp.sum(p**2) - 1 / jnp.sqrt(jnp.sum(q**2))
    )  # fmt: skip
    e, anomaly = 0.6, 2.0  # a = μ = 1: mean motion 1; outbound, past pericentre
    b, radius = np.sqrt(1 - e**2), 1 - e * np.cos(anomaly)
    q0 = jnp.array([np.cos(anomaly) - e, b * np.sin(anomaly)])
    p0 = jnp.array([-np.sin(anomaly), b * np.cos(anomaly)]) / radius
    # r·ṙ rises through zero at pericentre only (it falls through at apocentre)
    pericentre = diffrax.Event(lambda t, y, args: jnp.dot(*y), direction=True)
    run = lj.simulate(kepler, (q0, p0), t1=20.0, solver=TAYLOR, event=pericentre)
    mean_anomaly = anomaly - e * np.sin(anomaly)  # Kepler's equation
    assert run.ts[0] == pytest.approx(2 * np.pi - mean_anomaly, rel=1e-13)
    np.testing.assert_allclose(run.q[0], [1 - e, 0.0], atol=1e-12)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_saves_and_the_mask_match_the_heyoka_route():
    pytest.importorskip("heyoka")
    stops = diffrax.Event(
        (lambda t, y, args: y[0] - 0.25, lambda t, y, args: y[1] + 0.5)
    )  # fmt: skip
    ts = jnp.linspace(0.0, 4.0, 9)
    runs = [
        lj.simulate(PENDULUM, (0.5, 0.0), t1=4.0, ts=ts, solver=solver, event=stops)
        for solver in (TAYLOR, lj.Taylor(backend="heyoka", rtol=1e-15, atol=1e-15))
    ]
    jax_run, heyoka_run = runs
    # q falls from 0.5 to 0.25 before q̇ reaches -0.5 (q̇² = 2(cos q - cos 0.5))
    assert [bool(m) for m in jax_run.stats["event_mask"]] == [True, False]
    assert [bool(m) for m in heyoka_run.stats["event_mask"]] == [True, False]
    assert jax_run.result == diffrax.RESULTS.event_occurred
    np.testing.assert_array_equal(np.isinf(jax_run.ts), np.isinf(heyoka_run.ts))
    assert 0 < np.isinf(jax_run.ts).sum() < ts.size
    np.testing.assert_allclose(jax_run.q, heyoka_run.q, rtol=1e-14, atol=1e-15)


def test_boolean_conditions_are_refused_by_name():
    boolean = diffrax.Event(lambda t, y, args: y[0] < 0)
    with pytest.raises(ValueError, match="real-valued"):
        lj.simulate(PENDULUM, (0.5, 0.0), t1=5.0, solver=TAYLOR, event=boolean)
