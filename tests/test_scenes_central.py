"""Kepler scenes against their closed forms, in both coordinate forms.

One orbit at eccentricities 0, 0.6 and 0.99 (a vmap over scenes), integrated with
diffrax's adaptive Dopri8 at rtol = atol = 1e-14 (~410 steps at e = 0.99; fixed steps
would need to be tiny near that periapsis, where the speed is 14× the mean, and
at 1e-12 the velocity back at periapsis is off by 7e-8 of itself) — must follow Kepler's
equation, close after T = 2π√(a³/μ), keep E = −mμ/2a, ℓ and the Laplace–Runge–Lenz
vector at their closed-form values, and agree between the Cartesian Hamiltonian and
the polar Lagrangian. Relative errors ≤ 1e-8 throughout.
"""

import functools

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.scenes.central import (
    SCENES,
    KeplerCartesian,
    KeplerPolar,
    eccentric_anomaly,
)

ECCENTRICITIES = (0.0, 0.6, 0.99)
SAMPLES_PER_ORBIT = 9
TOLERANCE = 1e-8
FORMS = (KeplerCartesian, KeplerPolar)


def run_one_orbit(scene):
    """One period from periapsis, saved at 9 equally spaced times.

    Returns the trajectory, its Cartesian (position, velocity) and the checks.
    """
    period = scene.period()
    trajectory = lj.simulate(
        scene,
        scene.initial_state(),
        t1=period,
        ts=period * jnp.linspace(0.0, 1.0, SAMPLES_PER_ORBIT),
        solver=diffrax.Dopri8(),
        rtol=1e-14,
        atol=1e-14,
    )
    # Derived quantities (q̇, energy) are taken per trajectory, inside the vmap.
    cartesian = scene.cartesian_state(trajectory.q, trajectory.qdot)
    return trajectory, cartesian, scene.checks(trajectory)


# One compilation per coordinate form, shared by every batch of three scenes.
run_orbits = jax.jit(jax.vmap(run_one_orbit))


@functools.cache
def eccentricity_sweep(form):
    scenes = jax.vmap(lambda e: form(eccentricity=e))(jnp.array(ECCENTRICITIES))
    return scenes, *run_orbits(scenes)


def relative_error(measured, expected, scale):
    return float(np.max(np.abs(np.asarray(measured) - np.asarray(expected))) / scale)


def assert_checks_pass(scene, checks):
    """Every closed-form check of one scene within TOLERANCE, on its natural scale."""
    mass, mu = float(scene.mass), float(scene.gravitational_parameter)
    scales = {
        "position": float(scene.semi_major_axis),
        "energy": abs(float(scene.energy())),
        "angular momentum": float(scene.angular_momentum()),
        # |A| = m²μe vanishes on a circle, so measure it against m²μ.
        "Laplace-Runge-Lenz vector": mass**2 * mu,
    }
    assert set(checks) == set(scales)
    for name, (measured, expected) in checks.items():
        error = relative_error(measured, expected, scales[name])
        assert error <= TOLERANCE, f"{name}: relative error {error:.2e}"


def scene_at(scenes, index):
    return jax.tree_util.tree_map(lambda leaf: leaf[index], scenes)


def checks_at(checks, index):
    return {name: (m[index], e[index]) for name, (m, e) in checks.items()}


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize("form", FORMS, ids=lambda form: form.__name__)
@pytest.mark.parametrize("index", range(len(ECCENTRICITIES)), ids=ECCENTRICITIES)
def test_orbit_matches_keplers_equation_and_conserves_e_l_and_lenz(form, index):
    scenes, _, _, checks = eccentricity_sweep(form)
    assert_checks_pass(scene_at(scenes, index), checks_at(checks, index))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize("form", FORMS, ids=lambda form: form.__name__)
def test_orbit_closes_after_one_period(form):
    scenes, trajectories, (positions, velocities), _ = eccentricity_sweep(form)
    for index in range(len(ECCENTRICITIES)):
        scene = scene_at(scenes, index)
        start = scene.orbit_state(jnp.asarray(0.0))  # the periapsis start
        end = positions[index, -1], velocities[index, -1]
        assert relative_error(end[0], start[0], float(scene.semi_major_axis)) < 1e-8
        assert relative_error(end[1], start[1], float(scene.periapsis_speed())) < 1e-8
    if form is KeplerPolar:
        # θ is not wrapped: exactly one revolution.
        assert np.allclose(trajectories.q[:, -1, 1], 2 * np.pi, rtol=0, atol=1e-8)


@pytest.mark.integration  # compile-heavy (10–15 s): CI runs it in its integration step
def test_cartesian_and_polar_forms_agree():
    _, _, from_hamiltonian, _ = eccentricity_sweep(KeplerCartesian)
    _, _, from_lagrangian, _ = eccentricity_sweep(KeplerPolar)
    for index, e in enumerate(ECCENTRICITIES):
        speed = float(np.sqrt((1 + e) / (1 - e)))  # periapsis speed, a = μ = 1
        for part, scale in ((0, 1.0), (1, speed)):
            error = relative_error(
                from_hamiltonian[part][index], from_lagrangian[part][index], scale
            )
            assert error < 1e-8


@pytest.mark.integration  # a long run; CI runs it in its integration step (default-suite time)
def test_closed_forms_follow_the_parameters():
    # (m, μ, a, e): not the natural units, so a missing factor would show.
    parameters = np.array(
        [[2.0, 3.0, 1.5, 0.3], [0.5, 0.1, 4.0, 0.8], [3.0, 40, 0.2, 0]]
    )
    mass, mu, a, e = parameters.T
    scenes = jax.vmap(
        lambda m, k, s, x: KeplerCartesian(
            eccentricity=x, semi_major_axis=s, gravitational_parameter=k, mass=m
        )
    )(*map(jnp.asarray, (mass, mu, a, e)))
    assert np.allclose(scenes.period(), 2 * np.pi * np.sqrt(a**3 / mu), rtol=1e-14)
    assert np.allclose(scenes.energy(), -mass * mu / (2 * a), rtol=1e-14)
    _, _, checks = run_orbits(scenes)
    for index in range(len(parameters)):
        assert_checks_pass(scene_at(scenes, index), checks_at(checks, index))


@pytest.mark.parametrize(
    "scene, solver",
    [
        # A SeparableHamiltonian admits the explicit splitting methods; a Lagrangian
        # goes through its Legendre transform (the trajectory then stores p).
        (KeplerCartesian(), lj.KahanLi8()),
        (KeplerPolar(), lj.GaussLegendre(stages=3)),
    ],
    ids=["KeplerCartesian-KahanLi8", "KeplerPolar-GaussLegendre3"],
)
def test_symplectic_solvers_close_the_orbit_at_the_default_step(scene, solver):
    trajectory = lj.simulate(
        scene,
        scene.initial_state(),
        t1=scene.default_t1,
        dt=scene.default_dt,
        solver=solver,
    )
    assert float(scene.period()) == pytest.approx(scene.default_t1, rel=1e-15)
    assert_checks_pass(scene, scene.checks(trajectory))


def test_eccentric_anomaly_solves_keplers_equation():
    mean_anomaly = jnp.linspace(-10.0, 10.0, 2001)
    for e in (0.0, 0.5, 0.99, 0.999):
        anomaly = eccentric_anomaly(mean_anomaly, jnp.asarray(e))
        residual = anomaly - e * jnp.sin(anomaly) - jnp.mod(mean_anomaly, 2 * jnp.pi)
        assert float(jnp.max(jnp.abs(residual))) < 1e-13
        assert float(jnp.min(anomaly)) >= 0 and float(jnp.max(anomaly)) < 2 * np.pi


def test_module_lists_its_scenes():
    assert (KeplerCartesian, KeplerPolar) == SCENES
