"""Events on the step polynomial with `lj.Taylor(backend="heyoka")`: event times
against closed forms (the pendulum's quarter period, a projectile's flight),
diffrax's conventions for saves and masks, and what is refused by name."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj

pytest.importorskip("heyoka")

HEYOKA = lj.Taylor(backend="heyoka", rtol=1e-15, atol=1e-15)
PENDULUM = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))
CROSSES_ZERO = diffrax.Event(lambda t, y, args: y[0])


def quarter_period(theta0):
    """K(sin²(θ₀/2)) for ω₀ = 1, by Gauss's K(m) = π / (2 AGM(1, √(1 - m))) in
    NumPy (AGM converges quadratically: 8 iterations reach float64)."""
    a, b = np.ones_like(theta0), np.cos(np.asarray(theta0) / 2)
    for _ in range(8):
        a, b = (a + b) / 2, np.sqrt(a * b)
    return np.pi / (a + b)


def test_the_pendulum_reaches_the_bottom_after_a_quarter_period():
    for theta0 in (0.5, 2.0, 3.0):
        run = lj.simulate(PENDULUM, (theta0, 0.0), t1=20.0, solver=HEYOKA,
                          event=CROSSES_ZERO)  # fmt: skip
        assert run.result == diffrax.RESULTS.event_occurred
        assert run.ts[0] == pytest.approx(quarter_period(theta0), rel=1e-14)
        assert abs(run.q[0]) < 1e-14  # the saved state is the one at the event
        energy = 1 - np.cos(theta0)  # all kinetic at the bottom
        assert run.qdot[0] == pytest.approx(-np.sqrt(2 * energy), rel=1e-13)


def test_a_projectile_from_the_ground_lands_at_its_closed_form_time():
    projectile = lj.Lagrangian(
        lambda q, v: 0.5 * jnp.sum(v**2) - 9.81 * q[1]
    )  # fmt: skip
    lands = diffrax.Event(lambda t, y, args: y[0][1], direction=False)
    y0 = (jnp.zeros(2), jnp.array([3.0, 4.0]))  # the condition is 0 at t0
    run = lj.simulate(projectile, y0, t1=5.0, solver=HEYOKA, event=lands)
    flight = 2 * 4.0 / 9.81
    assert run.ts[0] == pytest.approx(flight, rel=1e-14)
    np.testing.assert_allclose(run.q[0], [3.0 * flight, 0.0], atol=1e-13)


def test_saves_after_the_event_and_the_mask_follow_diffrax():
    stops = diffrax.Event(
        (lambda t, y, args: y[0] - 0.25, lambda t, y, args: y[1] + 0.5)
    )  # fmt: skip
    ts = jnp.linspace(0.0, 4.0, 9)
    run = lj.simulate(PENDULUM, (0.5, 0.0), t1=4.0, ts=ts, solver=HEYOKA, event=stops)
    end = lj.simulate(PENDULUM, (0.5, 0.0), t1=4.0, solver=HEYOKA, event=stops)
    # q falls from 0.5 to 0.25 before q̇ reaches -0.5 (q̇² = 2(cos q - cos 0.5))
    assert [bool(m) for m in run.stats["event_mask"]] == [True, False]
    assert end.q[0] == pytest.approx(0.25, abs=1e-14)
    after = np.asarray(ts) > end.ts[0]
    assert 0 < after.sum() < ts.size
    assert (np.isinf(run.ts) == after).all() and (np.isinf(run.q) == after).all()
    np.testing.assert_allclose(run.q[0], 0.5)


@pytest.mark.integration  # compiles heyoka's batch integrator with an event
def test_events_of_a_batch_under_vmap():
    amplitudes = jnp.linspace(0.2, 3.0, 5)

    def quarter(theta0):
        run = lj.simulate(PENDULUM, (theta0, 0.0), t1=20.0, solver=HEYOKA,
                          event=CROSSES_ZERO)  # fmt: skip
        return run.ts[0]

    expected = quarter_period(np.asarray(amplitudes))
    np.testing.assert_allclose(jax.vmap(quarter)(amplitudes), expected, rtol=1e-14)


def test_boolean_conditions_are_refused_by_name():
    boolean = diffrax.Event(lambda t, y, args: y[0] < 0)
    with pytest.raises(ValueError, match="real-valued"):
        lj.simulate(PENDULUM, (0.5, 0.0), t1=5.0, solver=HEYOKA, event=boolean)
