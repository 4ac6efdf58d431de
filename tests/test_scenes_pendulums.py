"""Pendulum scenes against their closed forms (lagjax/scenes/pendulums.py)."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import lagjax as lj
from lagjax.sampled_signals import zero_crossing_times
from lagjax.scenes.pendulums import DoublePendulum, SimplePendulum
from lagjax.special_functions import (
    complete_elliptic_k,
    complete_elliptic_k_from_complement,
)


@eqx.filter_jit
def run_saved(scene, y0, solver, dt, t1, samples):
    """Fixed steps from y0, saved at equally spaced times that fall on steps."""
    ts = jnp.linspace(0.0, t1, samples)
    return lj.simulate(scene, y0, t1=t1, dt=dt, solver=solver, ts=ts)


def test_complete_elliptic_k_by_the_agm():
    assert np.isclose(complete_elliptic_k(0.0), np.pi / 2, rtol=1e-15, atol=0)
    # Singular values: K(1/√2) = Γ(1/4)²/(4√π); K(sin 15°) and K(sin 75°) are
    # 3^{1/4} and 3^{3/4} times Γ(1/3)³/(2^{7/3}π).
    lemniscatic = math.gamma(0.25) ** 2 / (4 * math.sqrt(math.pi))
    assert np.isclose(complete_elliptic_k(0.5), lemniscatic, rtol=1e-15, atol=0)
    third = math.gamma(1 / 3) ** 3 / (2 ** (7 / 3) * math.pi)
    for degrees, power in ((15, 0.25), (75, 0.75)):
        modulus = math.sin(math.radians(degrees))
        assert np.isclose(
            complete_elliptic_k(modulus**2), 3**power * third, rtol=1e-14, atol=0
        )
    # Near k = 1: K = L + (k′²/4)(L − 1) + O(k′⁴L), L = ln(4/k′) (A&S §17.3);
    # from k′ itself, since k = √(1 − k′²) would already have lost k′'s digits.
    complement = 1e-5
    logarithm = np.log(4 / complement)
    asymptotic = logarithm + complement**2 / 4 * (logarithm - 1)
    assert np.isclose(
        complete_elliptic_k_from_complement(complement**2),
        asymptotic,
        rtol=1e-14,
        atol=0,
    )


def test_zero_crossings_of_a_sampled_cosine():
    ts = jnp.linspace(0.0, 7.0, 71)  # 0.1 apart: ~1/16 of the period 2π/ω
    omega = 1.0
    x, xdot = jnp.cos(omega * ts), -omega * jnp.sin(omega * ts)
    crossings = jax.jit(zero_crossing_times, static_argnums=3)(ts, x, xdot, 3)
    assert np.allclose(crossings[:2], [np.pi / 2, 3 * np.pi / 2], rtol=1e-6, atol=0)
    assert np.isnan(crossings[2])  # only two crossings in [0, 7]


def test_pendulum_period_series_at_small_amplitude():
    # T = T₀(1 + θ₀²/16 + 11θ₀⁴/3072 + 173θ₀⁶/737280 + …) (Landau & Lifshitz §11).
    theta = 0.1
    series = 1 + theta**2 / 16 + 11 * theta**4 / 3072 + 173 * theta**6 / 737280
    scene = SimplePendulum(amplitude=theta, length=2.0)
    expected = 2 * np.pi * np.sqrt(2.0 / 9.81) * series
    assert np.isclose(scene.period(), expected, rtol=1e-12, atol=0)


@pytest.mark.integration  # a long run; CI runs it in its integration step (default-suite time)
def test_pendulum_period_measured_at_150_and_179_9_degrees():
    # Near the separatrix the period is sensitive to the energy: δT/T =
    # δE/(4mgl k′²K) ≈ 4e4 δE/mgl at 179.9°. Yoshida6 at h = 0.01 (ω₀h = 0.03)
    # keeps E to 2e-11 relative, an O(h⁶) oscillation that nearly vanishes at the
    # turning points (p and the force small) that set the period. Measured period
    # errors: 3.5e-12 (150°) and 1.2e-12 (179.9°).
    amplitudes = np.radians([150.0, 179.9])

    @eqx.filter_jit
    def measure(scene):
        run = run_saved(scene, scene.initial_state(), lj.Yoshida6(), 0.01, 9.0, 901)
        return scene.checks(run)

    per_scene = [measure(SimplePendulum(amplitude=a)) for a in amplitudes]
    checks = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *per_scene)
    measured, expected = checks["period"]
    assert np.allclose(measured, expected, rtol=1e-8, atol=0)
    assert np.isclose(expected[1], 10.7662932872, rtol=1e-10, atol=0)
    energy, start_energy = checks["energy"]
    assert np.allclose(energy, start_energy, rtol=1e-10, atol=0)
    # Near θ₀ = π the period diverges as (4/ω₀)[L + (k′²/4)(L − 1)], L = ln(4/k′).
    complement = np.cos(amplitudes[1] / 2)
    logarithm = np.log(4 / complement)
    asymptotic = 4 / np.sqrt(9.81) * (logarithm + complement**2 / 4 * (logarithm - 1))
    assert np.isclose(expected[1], asymptotic, rtol=1e-10, atol=0)


def test_double_pendulum_normal_modes_against_the_secular_equation():
    @eqx.filter_jit
    def autodiff_modes(scene):
        omegas, modes = lj.normal_modes(scene.system(), jnp.zeros(2), scene)
        kinetic, _ = lj.stiffness_matrices(scene.system(), jnp.zeros(2), scene)
        return omegas, modes.T @ kinetic @ scene.normal_mode_shapes()

    for scene in (
        DoublePendulum(),
        DoublePendulum(masses=(1.0, 0.3), lengths=(1.0, 0.6), gravity=9.0),
    ):
        omegas, overlap = autodiff_modes(scene)
        assert np.allclose(omegas, scene.normal_mode_frequencies(), rtol=1e-12, atol=0)
        assert np.allclose(np.abs(overlap), np.eye(2), rtol=0, atol=1e-12)
    equal = DoublePendulum()
    expected = np.sqrt((2 + np.array([-1, 1]) * np.sqrt(2)) * 9.81)
    assert np.allclose(equal.normal_mode_frequencies(), expected, rtol=1e-14, atol=0)
    shapes = equal.normal_mode_shapes()
    assert np.allclose(
        shapes[1] / shapes[0], [np.sqrt(2), -np.sqrt(2)], rtol=1e-14, atol=0
    )


def spectral_frequencies(ts, signal, count):
    """The `count` strongest angular frequencies of a sampled signal, ascending.

    Returns (coarse, refined): the peaks of a Hann-windowed FFT, whose resolution
    is one bin, 2π/duration; then a Levenberg–Marquardt fit of
    Σ aₖ cos ωₖt + bₖ sin ωₖt started there, limited only by the signal itself.
    """
    spectrum = np.abs(np.fft.rfft((signal - signal.mean()) * np.hanning(len(ts))))
    omegas = 2 * np.pi * np.fft.rfftfreq(len(ts), d=ts[1] - ts[0])
    inner = spectrum[1:-1]
    peaks = np.nonzero((inner > spectrum[:-2]) & (inner >= spectrum[2:]))[0] + 1
    coarse = np.sort(omegas[peaks[np.argsort(spectrum[peaks])[-count:]]])
    phases = ts[:, None] * coarse
    basis = np.concatenate([np.cos(phases), np.sin(phases)], axis=1)
    amplitudes = np.linalg.lstsq(basis, signal, rcond=None)[0]

    def residual(parameters, _):
        omega, cosine, sine = parameters
        phase = ts[:, None] * omega
        return jnp.cos(phase) @ cosine + jnp.sin(phase) @ sine - signal

    start = (jnp.asarray(coarse), amplitudes[:count], amplitudes[count:])
    solver = optx.LevenbergMarquardt(rtol=1e-13, atol=1e-13)
    fit = optx.least_squares(residual, solver, start, max_steps=100)
    return coarse, np.asarray(fit.value[0])


def double_pendulum_run(scene, start, t1=100.0):
    """GaussLegendre(3) at h = 0.0025, saved every 0.1 s (one compilation per t1)."""
    solver = lj.GaussLegendre(stages=3)
    return run_saved(scene, start, solver, 0.0025, t1, round(10 * t1) + 1)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_double_pendulum_small_oscillation_frequencies_from_a_trajectory():
    # θ₁ = 1e-5 rad excites both modes. The amplitude lowers the frequencies by
    # O(θ²): the fit below measured 6e-13 and 4.5e-11 (4.5e-9 for the fast mode
    # at θ₁ = 1e-4). Fitted to θ₁ over 100 s.
    scene = DoublePendulum()
    run = double_pendulum_run(scene, (jnp.array([1e-5, 0.0]), jnp.zeros(2)))
    ts, angle = np.asarray(run.ts), np.asarray(run.q[:, 0])
    coarse, refined = spectral_frequencies(ts, angle, 2)
    expected = np.asarray(scene.normal_mode_frequencies())  # √((2 ∓ √2) g/l)
    assert np.all(np.abs(coarse - expected) < 2 * np.pi / 100.0)  # one FFT bin
    assert np.allclose(refined, expected, rtol=1e-9, atol=0)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize(
    "t1", [100.0, pytest.param(1000.0, marks=pytest.mark.slow)], ids=["100s", "1000s"]
)
def test_double_pendulum_chaotic_run_conserves_energy(t1):
    # GaussLegendre(3) is symplectic: its energy error stays bounded, ∝ h⁶
    # (1.8e-11 at h = 0.0025 on θ = (2, 2.5) over 10 s).
    scene = DoublePendulum()
    run = double_pendulum_run(scene, scene.initial_state(), t1)
    energy, start_energy = scene.checks(run)["energy"]
    assert np.max(np.abs(energy - start_energy)) / abs(start_energy[0]) < 1e-10


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_double_pendulum_is_chaotic_at_large_amplitude():
    # Starts 1e-9 rad apart part company within 100 s at large amplitude; at
    # small amplitude (linear, regular) the gap stays at the 1e-9 level.
    scene = DoublePendulum()
    nudge = jnp.array([1e-9, 0.0])

    def final_gap(q0):
        runs = [double_pendulum_run(scene, (q, jnp.zeros(2))) for q in (q0, q0 + nudge)]
        return np.max(np.abs(runs[0].q[-1] - runs[1].q[-1]))

    assert final_gap(jnp.array([2.0, 2.5])) > 1e-2
    assert final_gap(jnp.array([0.01, 0.0])) < 1e-8
