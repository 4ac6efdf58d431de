"""Rotating and accelerated frames: each scene's run against its closed form."""

import functools

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.scenes import earth, rotating
from lagjax.scenes.earth import (
    EastwardDeflection,
    FoucaultPendulum,
    PlumbLine,
    bob_offset,
)
from lagjax.scenes.rotating import (
    AcceleratedFrameParticle,
    BeadOnRotatingWire,
    SpinningFrameParticle,
    inertial_motion,
)

SCENES = earth.SCENES + rotating.SCENES

# Tight enough that integration error is far below every tolerance asserted here.
TIGHT = dict(solver=diffrax.Dopri8(), rtol=1e-12, atol=1e-12)
FOUCAULT_WINDOW = 300.0  # s: ≈ 48 swings; the plane turns 0.015 rad at 45°


def degrees(*values):
    return np.deg2rad(np.array(values))


def per_latitude(compiled, latitudes):
    """`compiled(latitude)` for each latitude, its outputs stacked as NumPy arrays.

    One compile serves every latitude: vmapping the adaptive runs over the
    latitudes instead costs ~1.7× the trace and compile time of one run."""
    outputs = [compiled(latitude) for latitude in latitudes]
    return jax.tree_util.tree_map(lambda *xs: np.stack(xs), *outputs)


@eqx.filter_jit
def run(scene, y0, ts):
    """A tight run saved at `ts` and the scene's checks on it; compiled once per
    scene class, not per instance."""
    trajectory = lj.simulate(scene, y0, t1=ts[-1], ts=ts, **TIGHT)
    return trajectory, scene.checks(trajectory)


@jax.jit
def foucault_rate(latitude):
    scene = FoucaultPendulum(latitude=latitude)
    ts = jnp.linspace(0.0, FOUCAULT_WINDOW, 1501)  # ≈ 31 samples per swing
    swings = lj.simulate(
        scene, scene.initial_state(), t1=FOUCAULT_WINDOW, ts=ts, **TIGHT
    )
    angle = scene.plane_angle(swings.q, swings.qdot)
    return dict(
        measured=scene.measured_precession_rate(swings),
        turned=angle[-1] - angle[0],
        expected=scene.precession_rate(),
        airy=scene.airy_correction(),
    )


def test_foucault_precession_rate_follows_sin_latitude():
    latitudes = degrees(0.0, 30.0, 45.0, 90.0, -45.0)
    found = per_latitude(foucault_rate, latitudes)
    measured, turned, expected = found["measured"], found["turned"], found["expected"]
    earth_rate = float(FoucaultPendulum().earth_rate)
    np.testing.assert_allclose(expected, -earth_rate * np.sin(latitudes))
    # The plane turns > 0.01 rad in the window: ~400× the ±2.6e-5 rad wobble of the
    # pointwise angle, which the tapered fit averages down to ~1e-8 of the rate.
    assert np.all(np.abs(turned[1:]) > 0.01)
    # The brief's 1e-3, relative to each rate (to ω_E at the equator, where it is 0).
    scale = np.maximum(np.abs(expected), earth_rate * np.abs(np.cos(latitudes)))
    assert np.all(np.abs(measured - expected) < 1e-3 * scale)
    # Tighter: the finite-amplitude (Airy) correction −(3/8)(a/l)² = −3.9e-5 shows.
    with_airy = expected * (1 + found["airy"])
    assert np.all(np.abs(measured - with_airy) < 1e-6 * scale)
    assert np.all(np.abs(measured - expected) > 1e-5 * np.abs(expected))


def test_foucault_period_is_about_34_hours_at_45_degrees():
    scene = FoucaultPendulum()
    hours = scene.precession_period() / 3600
    sidereal_day_hours = 2 * np.pi / float(scene.earth_rate) / 3600
    np.testing.assert_allclose(hours, sidereal_day_hours * np.sqrt(2), rtol=1e-12)
    assert 33.8 < hours < 33.9


@pytest.mark.slow
def test_foucault_plane_turns_once_in_a_precession_period():
    scene = FoucaultPendulum()
    period = float(scene.precession_period())  # 1.2e5 s, 1.9e4 swings
    ts = jnp.linspace(0.0, period, 20001)
    day_and_a_half = lj.simulate(
        scene,
        scene.initial_state(),
        t1=period,
        ts=ts,
        solver=diffrax.Dopri8(),
        rtol=1e-10,
        atol=1e-10,
        max_steps=10**6,
    )
    angle = scene.plane_angle(day_and_a_half.q, day_and_a_half.qdot)
    full_turn = -2 * np.pi * (1 + scene.airy_correction())
    np.testing.assert_allclose(angle[-1] - angle[0], full_turn, rtol=1e-5)
    measured, expected = scene.checks(day_and_a_half)["precession rate"]
    np.testing.assert_allclose(measured, expected, rtol=1e-4)


@jax.jit
def fall(latitude):
    scene = EastwardDeflection(latitude=latitude)
    t = scene.fall_time()
    falling = lj.simulate(scene, scene.initial_state(), t1=t, ts=t[None], **TIGHT)
    return dict(
        landed=falling.q[-1],
        t=t,
        earth_rate=scene.earth_rate,
        first_order=scene.eastward_deflection(t),
        correction=scene.eastward_relative_correction(t),
        southward=scene.southward_deflection(t),
    )


def test_eastward_deflection_of_a_dropped_body():
    latitudes = degrees(0.0, 45.0, 60.0, -45.0)
    found = per_latitude(fall, latitudes)
    east, south = found["landed"][:, 1], found["landed"][:, 0]
    first_order = found["first_order"]
    assert np.all(east > 0.01)  # h = 100 m: 1.1–1.6 cm east, both hemispheres
    # The O(ω²) remainder, 0.6 (ω T)² ≈ 6.5e-8, bounds the first-order formula …
    remainder = float((found["earth_rate"][0] * found["t"][0]) ** 2)
    np.testing.assert_allclose(east, first_order, rtol=remainder)
    assert np.all(np.abs(east / first_order - 1) > 0.1 * remainder)
    # … and is itself −ω²(h/g + t²/10): what is left is O(ω⁴t⁴) and round-off.
    corrected = first_order * (1 + found["correction"])
    np.testing.assert_allclose(east, corrected, rtol=1e-12)
    # Second order: towards the equator (south in the north), 4 μm at 45°.
    np.testing.assert_allclose(south, found["southward"], rtol=1e-6, atol=1e-15)
    assert south[1] > 0 > south[3]


@jax.jit
def plumb_line(latitude):
    """Equilibrium by lj.equilibrium; the string's angle to g_eff there; δ; and the
    closed forms at `latitude`."""
    scene = PlumbLine(latitude=latitude)
    hanging = lj.equilibrium(scene.system(), jnp.zeros(2), args=scene)
    string = bob_offset(hanging, scene.length)
    pull = scene.effective_gravity(scene.site() + string)
    sine = jnp.linalg.norm(jnp.cross(pull, string)) / jnp.linalg.norm(pull)
    return dict(
        hanging=hanging,
        misalignment=sine / scene.length,
        measured=scene.string_deflection(hanging),
        exact=scene.hanging_offset()[:2],
        deflection=scene.deflection(),
        scene=scene,
    )


def test_plumb_line_deflection_against_latitude():
    latitudes = degrees(15.0, 30.0, 45.0, 60.0, 75.0)
    found = per_latitude(plumb_line, latitudes)
    hanging, misalignment = found["hanging"], found["misalignment"]
    measured, exact, scenes = found["measured"], found["exact"], found["scene"]
    np.testing.assert_allclose(hanging, exact, rtol=1e-10, atol=1e-15)
    assert np.all(hanging[:, 0] > 0)  # towards the equator
    assert np.all(np.abs(hanging[:, 1]) < 1e-15)  # in the meridian plane
    # The string lies along g_eff = g − ω × (ω × ρ) at the bob (eq. 1.30).
    assert np.all(misalignment < 1e-12)
    # The textbook δ(φ) holds at the site; the bob hangs l lower: −4 l/R.
    site_formula = found["deflection"]
    l_over_r = scenes.length / scenes.earth_radius
    np.testing.assert_allclose(measured, site_formula, rtol=5 * l_over_r[0])
    np.testing.assert_allclose(measured, site_formula * (1 - 4 * l_over_r), rtol=2e-9)
    # Leading order (ω²R/2g₀) sin 2φ: 0.1° at 45°, to O(ω²R/g₀) = 3.4e-3.
    centrifugal = scenes.earth_rate**2 * scenes.earth_radius
    surface_gravity = scenes.gravitational_parameter / scenes.earth_radius**2
    leading = centrifugal / (2 * surface_gravity) * np.sin(2 * latitudes)
    np.testing.assert_allclose(measured, leading, rtol=4e-3)
    assert 0.098 < np.rad2deg(measured[2]) < 0.1


@jax.jit
def plumb_bob_checks(scene):
    hanging = lj.simulate(scene, scene.initial_state(), t1=scene.default_t1, **TIGHT)
    return scene.checks(hanging)


def test_plumb_bob_stays_on_the_plumb_line():
    checks = plumb_bob_checks(PlumbLine())
    at_rest, on_line = checks["bob at rest on the plumb line"]
    np.testing.assert_allclose(at_rest, on_line, rtol=1e-9)
    np.testing.assert_allclose(*checks["plumb-line deflection"], rtol=1e-6)


def random_states(seed, count):
    rng = np.random.default_rng(seed)
    positions, velocities = rng.normal(size=(2, count, 3))
    times = rng.uniform(0.0, 3.0, count)
    return positions, velocities, times


@jax.jit
@functools.partial(jax.vmap, in_axes=(None, 0, 0, 0))
def derived_acceleration(scene, position, velocity, t):
    """q̈ from lagjax's Euler–Lagrange derivation of the scene's L."""
    return scene.system().acceleration(position, velocity, t, scene)


@jax.jit
def spinning_frame_closed_forms(scene, uniform, positions, velocities, times):
    """eq. 1.27 at the states, and g_eff = g − ω × (ω × r) in the uniform frame."""
    closed = jax.vmap(scene.frame_acceleration)(positions, velocities, times)
    omega = uniform.angular_velocity(0.0)
    g_eff = uniform.gravity - jnp.cross(omega, jnp.cross(omega, positions))
    return closed, g_eff


def test_spinning_frame_acceleration_has_every_fictitious_force():
    scene = SpinningFrameParticle()
    uniform = SpinningFrameParticle(spin_acceleration=0.0)
    positions, velocities, times = random_states(0, 8)
    closed, g_eff = spinning_frame_closed_forms(
        scene, uniform, positions, velocities, times
    )
    derived = derived_acceleration(scene, positions, velocities, times)
    np.testing.assert_allclose(derived, closed, rtol=1e-12, atol=1e-12)
    # At rest in a uniformly turning frame: g_eff = g − ω × (ω × r) (eq. 1.30).
    zero_times = np.zeros_like(times)
    at_rest = derived_acceleration(uniform, positions, 0 * velocities, zero_times)
    np.testing.assert_allclose(at_rest, g_eff, rtol=1e-13, atol=1e-13)


@jax.jit
def inertial_start(scene):
    """The spinning frame's start as seen from the inertial frame."""
    return inertial_motion(scene.to_inertial, *scene.initial_state(), 0.0)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_spinning_frame_matches_the_inertial_solution_turned_back():
    scene = SpinningFrameParticle()
    ts = np.linspace(0.0, scene.default_t1, 31)
    spinning, checks = run(scene, scene.initial_state(), ts)
    measured, closed = checks["position"]
    np.testing.assert_allclose(measured, closed, rtol=0, atol=1e-9)
    # The inertial problem integrated on its own (a frame that does not turn) ...
    inertial = SpinningFrameParticle(spin_rate=0.0, spin_acceleration=0.0)
    fixed, _ = run(inertial, inertial_start(scene), ts)
    # ... and turned into the spinning frame, agrees with the spinning-frame run.
    spinning_q, fixed_q = np.asarray(spinning.q), np.asarray(fixed.q)
    turned_back = jax.jit(type(scene).to_frame)(scene, fixed_q, ts)
    np.testing.assert_allclose(spinning_q, turned_back, atol=1e-9)
    assert np.max(np.abs(spinning_q - fixed_q)) > 1.0  # the frames do differ


def test_accelerated_frame_feels_minus_m_times_the_frame_acceleration():
    scene = AcceleratedFrameParticle()
    positions, velocities, times = random_states(1, 8)
    derived = derived_acceleration(scene, positions, velocities, times)
    force = jax.jit(type(scene).fictitious_force)(scene, times)
    closed = np.asarray(scene.gravity) + force / float(scene.mass)
    np.testing.assert_allclose(derived, closed, rtol=1e-12, atol=1e-12)
    ts = np.linspace(0.0, scene.default_t1, 31)
    _, checks = run(scene, scene.initial_state(), ts)
    np.testing.assert_allclose(*checks["position"], rtol=0, atol=1e-9)


def test_bead_on_rotating_wire_flies_out_exponentially():
    scene = BeadOnRotatingWire()
    ts = np.linspace(0.0, scene.default_t1, 21)
    trajectory, checks = run(scene, scene.initial_state(), ts)
    # ~1e-9: diffrax's Dopri8 dense output at `ts`; its steps themselves are at 1e-12.
    np.testing.assert_allclose(*checks["radius"], rtol=1e-8)
    np.testing.assert_allclose(*checks["Jacobi integral"], rtol=1e-8)
    r, rdot = np.asarray(trajectory.q), np.asarray(trajectory.qdot)
    assert r[-1] > 5 * r[0]  # turned round, then out along e^{ωt}
    mass, omega = float(scene.mass), float(scene.angular_velocity)
    kinetic = 0.5 * mass * (rdot**2 + (omega * r) ** 2)
    assert kinetic[-1] > 10 * kinetic[0]  # the wire does work: energy is not conserved


def test_every_scene_is_listed_and_parameters_are_arrays():
    assert len(SCENES) == 6
    for scene_class in SCENES:
        scene = scene_class()
        leaves = jax.tree_util.tree_leaves(scene)
        assert leaves and all(isinstance(leaf, jax.Array) for leaf in leaves)
        assert scene_class.default_t1 > 0 and scene_class.default_dt > 0
