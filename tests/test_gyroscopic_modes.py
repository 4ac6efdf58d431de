"""Small oscillations with gyroscopic terms against closed forms (issue 15).

Each system has a term linear in q̇ (Coriolis, vector potential) that the T/V
normal-mode problem would drop: the L4 point and Routh's mass ratio, the Foucault
pendulum's mode splitting, a charged oscillator in a magnetic field.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.scenes.earth import FoucaultPendulum
from tests.helpers import relative_close

ROUTH_MASS_RATIO = (1 - np.sqrt(23 / 27)) / 2  # 0.0385208…


def restricted_three_body(q, qd, t, mu):
    """Rotating frame, unit separation and angular velocity, primaries on the x-axis."""
    x, y = q[0], q[1]
    inertial_velocity = jnp.stack([qd[0] - y, qd[1] + x])
    r1 = jnp.sqrt((x + mu) ** 2 + y**2)
    r2 = jnp.sqrt((x - 1 + mu) ** 2 + y**2)
    return 0.5 * jnp.sum(inertial_velocity**2) + (1 - mu) / r1 + mu / r2


THREE_BODY = lj.Lagrangian(restricted_three_body)


def l4_closed_form(mu):
    """L4's position and its eigenvalues from λ⁴ + λ² + (27/4)μ(1−μ) = 0."""
    position = np.array([0.5 - mu, np.sqrt(3) / 2])
    return position, np.roots([1, 0, 1, 0, 27 / 4 * mu * (1 - mu)])


def test_l4_frequencies_match_the_quartic():
    mu = jnp.asarray(0.01)  # an array, not a Python float: one compilation for all μ
    q4 = lj.relative_equilibrium(THREE_BODY, jnp.array([0.4, 0.8]), mu)
    position, roots = l4_closed_form(mu)
    assert relative_close(q4, position, 1e-12)
    result = lj.normal_modes(THREE_BODY, q4, mu)
    expected = np.sort(np.abs(roots.imag))[::2]  # one of each ±iω pair
    assert relative_close(result.omegas, expected, 1e-10)
    assert relative_close(result.omegas, [0.268348, 0.963322], 2e-6)  # the issue's
    assert result.gyroscopic and result.labels() == ("stable", "stable")
    assert result.verdict() == "stable"


def test_l4_mode_shapes_solve_the_quadratic_eigenproblem():
    # (λ²M + λG + K) a = 0 with the textbook matrices at L4 (Murray & Dermott §3.8):
    # M = 1, G = [[0, −2], [2, 0]], K = −∂²Ω, Ω_xx = 3/4, Ω_yy = 9/4,
    # Ω_xy = (3√3/4)(1 − 2μ).
    mu = 0.01
    omegas, modes = lj.normal_modes(
        THREE_BODY, jnp.asarray(l4_closed_form(mu)[0]), jnp.asarray(mu)
    )
    gyro = np.array([[0.0, -2.0], [2.0, 0.0]])
    cross = 3 * np.sqrt(3) / 4 * (1 - 2 * mu)
    stiffness = -np.array([[0.75, cross], [cross, 2.25]])
    for omega, shape in zip(np.asarray(omegas), np.asarray(modes).T):
        lam = 1j * omega
        residual = (lam**2 * np.eye(2) + lam * gyro + stiffness) @ shape
        assert np.max(np.abs(residual)) < 1e-12
        assert np.isclose(np.vdot(shape, shape).real, 1.0, rtol=1e-12)  # aᴴMa = 1
    # The motions are ellipses, not lines: the shapes are genuinely complex.
    assert np.all(np.abs(np.asarray(modes).imag).max(axis=0) > 0.1)


@pytest.mark.parametrize("side", [-1, 1])
def test_routh_critical_mass_ratio(side):
    mu = ROUTH_MASS_RATIO * (1 + side * 1e-3)
    result = lj.normal_modes(
        THREE_BODY, jnp.asarray(l4_closed_form(mu)[0]), jnp.asarray(mu)
    )
    roots = l4_closed_form(mu)[1]
    if side < 0:
        assert result.verdict() == "stable"
        assert np.max(np.abs(np.asarray(result.growth_rates))) < 1e-12
        # Just below, the two frequencies crowd towards 1/√2.
        assert np.all(np.abs(np.asarray(result.omegas) - 2**-0.5) < 0.02)
    else:
        assert result.verdict() == "unstable"
        assert result.labels() == ("unstable", "unstable")
        # A Krein collision: λ = ±γ ± iω, both modes oscillate at ω ≈ 1/√2.
        growth = np.max(roots.real)
        assert relative_close(np.max(result.growth_rates), growth, 1e-8)
        assert relative_close(result.omegas, np.abs(roots.imag)[:2], 1e-8)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_foucault_modes_split_by_the_vertical_earth_rate():
    scene = FoucaultPendulum()
    pendulum = scene.system()
    # The bob hangs l below the pivot, so the centrifugal force tilts the line by
    # ~l ω_E² sin φ cos φ/(g/l) ≈ 2.6e-8 m: q = 0 is refused ...
    with pytest.raises(ValueError, match="residual generalized force"):
        lj.normal_modes(pendulum, jnp.zeros(2), scene)
    # ... and the equilibrium found instead.
    rest = lj.relative_equilibrium(scene, jnp.zeros(2))
    rate = float(scene.earth_rate)
    latitude, length = float(scene.latitude), float(scene.length)
    tilt = length**2 * rate**2 * np.sin(latitude) * np.cos(latitude) / scene.gravity
    assert relative_close(abs(rest[0]), tilt, 1e-6)
    omegas, modes = lj.normal_modes(pendulum, rest, scene)
    # ω± = √(g/l + Ω²) ± Ω, Ω = ω_E sin φ: half the splitting is the precession rate.
    half_split = 0.5 * float(omegas[1] - omegas[0])
    assert relative_close(half_split, rate * np.sin(latitude), 1e-7)
    # The modes are circular (|a_y| = |a_x|, a quarter period apart), one each way.
    ratio = np.asarray(modes[1] / modes[0])
    assert np.allclose(np.abs(ratio), 1.0, atol=1e-4)
    assert np.allclose(np.sort(np.angle(ratio)), [-np.pi / 2, np.pi / 2], atol=1e-4)


def charged_oscillator(q, qd, t, args):
    """L = ½m|ṙ|² − ½mω0²|r|² + (e/2)(B ẑ × r)·ṙ in the plane (course text §3.5)."""
    mass, charge, field, omega0 = args
    vector_potential = 0.5 * field * jnp.stack([-q[1], q[0]])
    return (
        0.5 * mass * jnp.sum(qd**2)
        - 0.5 * mass * omega0**2 * jnp.sum(q**2)
        + charge * jnp.dot(vector_potential, qd)
    )


def test_charged_oscillator_in_a_magnetic_field():
    mass, charge, field, omega0 = 2.0, 0.5, 3.0, 1.3
    cyclotron = charge * field / mass
    lag = lj.Lagrangian(charged_oscillator)
    result = lj.normal_modes(lag, jnp.zeros(2), (mass, charge, field, omega0))
    centre = np.sqrt(omega0**2 + cyclotron**2 / 4)
    expected = [centre - cyclotron / 2, centre + cyclotron / 2]
    assert relative_close(result.omegas, expected, 1e-12)
    assert result.verdict() == "stable"
    # Normalised to aᴴMa = 1 with the mass m.
    norms = np.einsum("ik,ik->k", np.conj(result.modes), mass * result.modes)
    assert np.allclose(norms, 1.0, rtol=1e-12)


def test_free_charge_has_a_cyclotron_mode_and_a_neutral_one():
    lag = lj.Lagrangian(charged_oscillator)
    mass, charge, field = 1.0, 1.0, 2.0
    result = lj.normal_modes(lag, jnp.zeros(2), (mass, charge, field, 0.0))
    # ω = eB/m, and ω = 0: the guiding centre stays put anywhere (marginal).
    assert abs(float(result.omegas[0])) < 1e-12
    assert relative_close(result.omegas[1], charge * field / mass, 1e-12)
    assert result.labels() == ("marginal", "stable")


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_gyroscopic_terms_are_never_dropped_silently():
    mu = jnp.asarray(0.01)
    q4 = jnp.asarray(l4_closed_form(0.01)[0])
    with pytest.raises(ValueError, match="gyroscopic"):
        lj.normal_modes(THREE_BODY, q4, mu, gyroscopic=False)
    # Under jit the detection cannot branch on values: a run-time error instead ...
    with pytest.raises(Exception, match="gyroscopic=True"):
        jax.block_until_ready(eqx.filter_jit(lj.normal_modes)(THREE_BODY, q4, mu))
    # ... and an explicit gyroscopic=True works under jit and vmap.
    frequencies = jax.vmap(
        lambda m: (
            lj.normal_modes(
                THREE_BODY, jnp.stack([0.5 - m, 0.75**0.5]), m, gyroscopic=True
            ).omegas
        )
    )(jnp.array([0.001, 0.01]))
    for m, row in zip([0.001, 0.01], np.asarray(frequencies)):
        roots = l4_closed_form(m)[1]
        assert relative_close(row, np.sort(np.abs(roots.imag))[::2], 1e-10)


def test_rotating_spherical_pendulum_in_redundant_coordinates():
    # A bob on a rod of length l, Cartesian (x, y, z) with |r| = l, seen from a frame
    # turning at Ω about the vertical: gyroscopic and constrained at once. In the
    # inertial frame the small swings are circles at √(g/l) either way; the frame
    # sees them at √(g/l) ∓ Ω (the centrifugal −Ω² and the Coriolis term combine).
    g, length, mass, spin = 9.81, 0.7, 2.0, 0.05

    def L(q, qd):
        inertial_velocity = qd + jnp.cross(jnp.array([0.0, 0.0, spin]), q)
        return 0.5 * mass * jnp.sum(inertial_velocity**2) - mass * g * q[2]

    lag = lj.Lagrangian(L, constraints=lambda q: jnp.sqrt(jnp.sum(q**2)) - length)
    result = lj.normal_modes(lag, jnp.array([0.0, 0.0, -length]))
    natural = np.sqrt(g / length)
    assert result.gyroscopic and result.modes.shape == (3, 2)
    assert relative_close(result.omegas, [natural - spin, natural + spin], 1e-12)
    # Horizontal circles: no vertical component, |a_x| = |a_y| a quarter apart.
    shapes = np.asarray(result.modes)
    assert np.max(np.abs(shapes[2])) < 1e-12
    assert np.allclose(np.abs(shapes[1] / shapes[0]), 1.0, rtol=1e-12)
