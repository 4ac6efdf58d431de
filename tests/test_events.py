"""Events: `simulate(..., event=diffrax.Event(...))` ends the run at the event, located
on the dense output to the method's accuracy — against closed forms."""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.scenes.central import KeplerCartesian
from lagjax.special_functions import complete_elliptic_k

PENDULUM = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: -jnp.cos(q))
THETA0 = 2.0


def angle(t, y, args, **kwargs):
    return y[0]


def quarter_period() -> float:
    """T/4 = K(sin²(θ0/2)) for the unit pendulum released at rest from θ0."""
    return float(complete_elliptic_k(jnp.asarray(np.sin(THETA0 / 2) ** 2)))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_pendulum_quarter_period_with_yoshida6_to_1e_9():
    run = lj.simulate(
        PENDULUM, (THETA0, 0.0), t1=3.0, dt=0.01, solver=lj.Yoshida6(),
        event=diffrax.Event(angle),
    )  # fmt: skip
    assert run.result == diffrax.RESULTS.event_occurred
    assert bool(run.stats["event_mask"])
    assert abs(float(run.ts[-1]) - quarter_period()) < 1e-9
    # The run ends at the event: the pendulum hangs straight down, at full speed.
    assert abs(float(run.q[-1])) < 1e-9
    speed = 2 * np.sin(THETA0 / 2)  # energy: p²/2 − cos 0 = −cos θ0
    assert abs(abs(float(run.p[-1])) - speed) < 1e-9


def test_adaptive_solver_event():
    run = lj.simulate(
        PENDULUM, (THETA0, 0.0), t1=3.0, solver=diffrax.Tsit5(), rtol=1e-12,
        atol=1e-12, event=diffrax.Event(angle),
    )  # fmt: skip
    assert abs(float(run.ts[-1]) - quarter_period()) < 1e-8


def test_event_condition_sees_the_callers_velocity():
    """A Lagrangian run by Gauss–Legendre integrates (q, p = 2q̇); the condition is
    written on q̇ and fires where energy conservation puts q̇ = −1:
    ½·2·q̇² − cos q = −cos θ0, so cos q = 1 + cos θ0."""
    lagrangian = lj.Lagrangian(lambda q, qdot: qdot**2 + jnp.cos(q))

    def velocity_reaches_minus_one(t, y, args, **kwargs):
        return y[1] + 1.0

    run = lj.simulate(
        lagrangian, (THETA0, 0.0), t1=3.0, dt=0.02, solver=lj.GaussLegendre(stages=3),
        event=diffrax.Event(velocity_reaches_minus_one),
    )  # fmt: skip
    assert run.result == diffrax.RESULTS.event_occurred
    assert abs(float(run.qdot[-1]) + 1.0) < 1e-10
    assert abs(float(run.q[-1]) - np.arccos(1 + np.cos(THETA0))) < 1e-9


def radial_velocity(t, y, args, **kwargs):
    q, p = y
    return jnp.dot(q, p)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_kepler_apoapsis_and_periapsis_passages():
    """From periapsis the radial velocity r·ṙ turns negative at apoapsis, T/2, and
    positive again at the next periapsis, T (Kepler's third law for T)."""
    scene = KeplerCartesian()
    period = float(scene.period())
    apoapsis = lj.simulate(
        scene, scene.initial_state(), t1=period, solver=lj.Yoshida6(),
        event=diffrax.Event(radial_velocity, direction=False),
    )  # fmt: skip
    half = float(apoapsis.ts[-1])
    assert abs(half - period / 2) < 1e-9 * period
    start = (apoapsis.q[-1], apoapsis.p[-1])
    periapsis = lj.simulate(
        scene, start, t0=half, t1=half + period, solver=lj.Yoshida6(),
        event=diffrax.Event(radial_velocity, direction=True),
    )  # fmt: skip
    assert abs(float(periapsis.ts[-1]) - period) < 1e-9 * period
    perihelion = float(jnp.linalg.norm(periapsis.q[-1]))
    expected = float(scene.semi_major_axis * (1 - scene.eccentricity))
    assert abs(perihelion - expected) < 1e-9
