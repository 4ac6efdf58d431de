"""Uniform-field scenes against their closed forms.

A charge in uniform E and B (Dopri8, rtol = atol = 1e-12, three cyclotron periods
sampled 16 times each, a vmap over five scenes) must follow the exact helix/drift
solution, and the cyclotron frequency eB/m, Larmor radius m v⊥/|e|B and drift E×B/B²
measured from its samples (circles fitted to the velocity hodograph and to the
positions in the drifting frame) must match the textbook values; its Lagrangian must give
the Lorentz force. Free fall and Atwood's machine (Störmer–Verlet, exact for a
constant force) must follow y0 + v0 t + ½ a t² with a = g and (M1 − M2) g/(M1 + M2).
Relative errors ≤ 1e-8 (1e-12 for the exact Störmer–Verlet runs).
"""

import functools

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.scenes.fields import (
    SCENES,
    AtwoodMachine,
    ChargeInUniformFields,
    FreeFall,
)

TOLERANCE = 1e-8
PERIODS, SAMPLES_PER_PERIOD = 3, 16

# (mass, charge, B, E, v0): pure B (a helix); crossed E ⊥ B; the same fields for a
# heavier negative charge (same drift, opposite gyration); a stronger field; and
# oblique fields with E‖ ≠ 0 (the guiding centre accelerates along B).
CHARGE_CASES = {
    "pure B": (1.0, 1.0, (0, 0, 1), (0, 0, 0), (1.0, 0, 0.3)),
    "crossed E, B": (1.0, 1.0, (0, 0, 1), (0.2, 0, 0), (1.0, 0, 0)),
    "crossed, e < 0": (3.0, -1.0, (0, 0, 1), (0.2, 0, 0), (1.0, 0, 0)),
    "strong B": (0.5, 2.0, (0, 0, 2), (0, 0.5, 0), (0.3, 0.4, 0)),
    "oblique": (2.0, 1.5, (1, 2, 2), (0.3, -0.6, 1.0), (0.5, -1.0, 0.2)),
}


def charge_scene(mass, charge, magnetic_field, electric_field, initial_velocity):
    return ChargeInUniformFields(
        mass=mass,
        charge=charge,
        magnetic_field=magnetic_field,
        electric_field=electric_field,
        initial_velocity=initial_velocity,
    )


@jax.jit
@jax.vmap
def run_charge(scene):
    samples = PERIODS * SAMPLES_PER_PERIOD
    ts = scene.cyclotron_period() * jnp.arange(samples + 1) / SAMPLES_PER_PERIOD
    trajectory = lj.simulate(
        scene,
        scene.initial_state(),
        t1=ts[-1],
        ts=ts,
        solver=diffrax.Dopri8(),
        rtol=1e-12,
        atol=1e-12,
    )
    return trajectory, scene.checks(trajectory)


@functools.cache
def charge_runs():
    columns = [np.array(column, dtype=float) for column in zip(*CHARGE_CASES.values())]
    scenes = jax.vmap(charge_scene)(*columns)
    trajectories, checks = run_charge(scenes)
    return scenes, trajectories, checks


def case_index(name):
    return list(CHARGE_CASES).index(name)


def measured(name, check):
    _, _, checks = charge_runs()
    return np.asarray(checks[check][0][case_index(name)])


def relative_error(measured, expected, scale):
    return float(np.max(np.abs(np.asarray(measured) - np.asarray(expected))) / scale)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize("name", CHARGE_CASES)
def test_charge_checks_pass(name):
    scenes, _, checks = charge_runs()
    index = case_index(name)
    scene = jax.tree_util.tree_map(lambda leaf: leaf[index], scenes)
    speed = float(jnp.linalg.norm(scene.initial_velocity))
    scales = {
        "position": float(jnp.max(jnp.abs(checks["position"][1][index]))),
        "drift velocity": speed,
        "signed gyrofrequency": float(scene.cyclotron_frequency()),
        "Larmor radius": float(scene.larmor_radius()),
        "energy": 0.5 * float(scene.mass) * speed**2,
    }
    assert set(checks) == set(scales)
    for check, (value, expected) in checks.items():
        error = relative_error(value[index], expected[index], scales[check])
        assert error <= TOLERANCE, f"{check}: relative error {error:.2e}"


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_measured_cyclotron_frequency_is_eb_over_m():
    # Ω = eB/m, signed: a positive charge turns clockwise about B (angle −Ωt).
    expected = {
        "pure B": 1.0,
        "crossed, e < 0": -1 / 3,
        "strong B": 8.0,
        "oblique": 2.25,
    }
    for name, omega in expected.items():
        gyrofrequency = measured(name, "signed gyrofrequency")
        assert relative_error(gyrofrequency, omega, abs(omega)) < TOLERANCE


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_measured_larmor_radius_is_m_v_perp_over_eb():
    # Pure B: v⊥ = |(1, 0)| = 1, so ρ = m v⊥/(eB) = 1. Crossed fields: v⊥ is taken
    # in the drift frame, v0 − v_E = (1, 0.2, 0), so ρ = √1.04 m/(|e|B).
    expected = {
        "pure B": 1.0,
        "crossed E, B": np.sqrt(1.04),
        "crossed, e < 0": 3 * np.sqrt(1.04),
        "strong B": 0.5 * np.hypot(0.3 - 0.25, 0.4) / (2 * 2),
    }
    for name, radius in expected.items():
        assert (
            relative_error(measured(name, "Larmor radius"), radius, radius) < TOLERANCE
        )


@pytest.mark.integration  # a long run; CI runs it in its integration step (default-suite time)
def test_measured_drift_is_e_cross_b_over_b_squared():
    # E = 0.2 x̂, B = ẑ: |v_E| = E/B = 0.2 along E×B = −ŷ, whatever the charge or mass.
    for name in ("crossed E, B", "crossed, e < 0"):
        drift = measured(name, "drift velocity")
        assert relative_error(drift, [0.0, -0.2, 0.0], 0.2) < TOLERANCE
    strong = measured("strong B", "drift velocity")  # E = 0.5 ŷ, B = 2 ẑ: 0.25 x̂
    assert relative_error(strong, [0.25, 0.0, 0.0], 0.25) < TOLERANCE
    assert relative_error(measured("pure B", "drift velocity"), 0.0, 1.0) < TOLERANCE


def test_lagrangian_gives_the_lorentz_force():
    # The course text eq. 3.88 from L of eq. 3.99: m r̈ = e (E + v × B).
    scene = charge_scene(*CHARGE_CASES["oblique"])
    lagrangian = scene.system()
    key_r, key_v = jax.random.split(jax.random.key(0))
    positions = jax.random.normal(key_r, (8, 3))
    velocities = jax.random.normal(key_v, (8, 3))
    accelerations = jax.vmap(lambda r, v: lagrangian.acceleration(r, v, 0.0, scene))(
        positions, velocities
    )
    lorentz = (scene.charge / scene.mass) * (
        scene.electric_field + jnp.cross(velocities, scene.magnetic_field)
    )
    assert np.allclose(accelerations, lorentz, rtol=1e-12, atol=1e-12)


def test_charge_checks_need_samples_less_than_half_a_period_apart():
    scenes, trajectories, _ = charge_runs()
    scene = jax.tree_util.tree_map(lambda leaf: leaf[0], scenes)
    trajectory = jax.tree_util.tree_map(lambda leaf: leaf[0], trajectories)
    # Every 9th of 16 samples per period: the gyration phase would alias.
    with pytest.raises(Exception, match="half a cyclotron"):
        jax.block_until_ready(scene.checks(every_nth_sample(trajectory, 9)))
    # Every 7th: 2⅝ periods, not whole ones; the circle fits do not need them.
    checks = eqx.filter_jit(lambda s, tr: s.checks(tr))(
        scene, every_nth_sample(trajectory, 7)
    )
    for name in ("drift velocity", "signed gyrofrequency", "Larmor radius"):
        assert relative_error(*checks[name], 1.0) < TOLERANCE, name


def every_nth_sample(trajectory, n):
    ys = jax.tree_util.tree_map(lambda leaf: leaf[::n], trajectory.ys)
    return eqx.tree_at(lambda tr: (tr.ts, tr.ys), trajectory, (trajectory.ts[::n], ys))


# --- Uniform gravity ------------------------------------------------------------------
GRAVITY_T1 = 0.4  # long enough to see the parabola, short enough to keep 0 < y < l
GRAVITY_TS = jnp.linspace(0.0, GRAVITY_T1, 9)
MASS_PAIRS = np.array([[3.0, 1.0], [1.0, 3.0], [2.0, 2.0], [5.0, 0.0]])


def run_exact(scene):
    """Störmer–Verlet is exact for a constant force, so only round-off remains."""
    trajectory = lj.simulate(
        scene,
        scene.initial_state(),
        t1=GRAVITY_T1,
        dt=0.01,
        ts=GRAVITY_TS,
        solver=lj.StormerVerlet(),
    )
    return trajectory.q, scene.checks(trajectory)


def test_atwood_machine_accelerates_at_the_textbook_rate():
    scenes = jax.vmap(lambda m1, m2: AtwoodMachine(mass_1=m1, mass_2=m2))(*MASS_PAIRS.T)
    _, checks = jax.jit(jax.vmap(run_exact))(scenes)
    m1, m2 = MASS_PAIRS.T
    textbook = (m1 - m2) * 9.81 / (m1 + m2)  # g/2, −g/2, 0, g
    assert np.allclose(checks["acceleration"][0], textbook, rtol=1e-12, atol=1e-12)
    for name, (value, expected) in checks.items():
        assert np.allclose(value, expected, rtol=1e-12, atol=1e-12), name


def test_free_fall_is_the_parabola_and_atwood_without_counterweight():
    fall = FreeFall(mass=2.0, initial_position=0.3, initial_velocity=-4.0)
    heights, checks = run_exact(fall)
    t = np.asarray(GRAVITY_TS)
    assert np.allclose(heights, 0.3 - 4.0 * t + 0.5 * 9.81 * t**2, rtol=1e-12)
    for name, (value, expected) in checks.items():
        assert np.allclose(value, expected, rtol=1e-12, atol=1e-12), name
    assert float(checks["acceleration"][0]) == pytest.approx(9.81, rel=1e-12)
    atwood = AtwoodMachine(
        mass_1=2.0, mass_2=0.0, initial_position=0.3, initial_velocity=-4.0
    )
    atwood_heights, _ = run_exact(atwood)
    assert np.allclose(atwood_heights, heights, rtol=1e-12, atol=1e-12)


def test_modules_list_their_scenes():
    assert (ChargeInUniformFields, AtwoodMachine, FreeFall) == SCENES
