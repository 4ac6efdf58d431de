"""Linear oscillator scenes against their closed forms (scenes/oscillators.py,
scenes/driven.py)."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.scenes import chains, driven, oscillators, pendulums
from lagjax.scenes.driven import DampedDrivenOscillator
from lagjax.scenes.oscillators import CoupledOscillators, HarmonicOscillator


def worst_relative_errors(checks):
    """{name: max |measured − expected| / max |expected|} over every saved time."""
    return {
        name: np.max(np.abs(measured - expected)) / np.max(np.abs(expected))
        for name, (measured, expected) in checks.items()
    }


@eqx.filter_jit
def run_saved(scene, solver, dt, t1, samples, rtol=1e-8):
    """A run from the scene's start, saved at `samples` equally spaced times.

    With a fixed step the saved times must fall on steps (the symplectic solvers
    interpolate linearly between them), so t1/(samples − 1) is a multiple of dt.
    """
    ts = jnp.linspace(0.0, t1, samples)
    return lj.simulate(
        scene, scene.initial_state(), t1=t1, dt=dt, solver=solver, ts=ts,
        rtol=rtol, atol=rtol,
    )  # fmt: skip


@eqx.filter_jit
def compiled_checked_run(scene, solver, dt, t1, samples, rtol):
    trajectory = run_saved(scene, solver, dt, t1, samples, rtol)
    return trajectory, scene.checks(trajectory), trajectory.energy()


def checked_run(scene, solver, dt, t1, samples, rtol=1e-8):
    """`run_saved`, the worst relative error of each of the scene's checks, the
    checks and the energy along the run, from one compiled call."""
    trajectory, checks, energy = compiled_checked_run(
        scene, solver, dt, t1, samples, rtol
    )
    checks = jax.tree_util.tree_map(np.asarray, checks)
    return trajectory, worst_relative_errors(checks), checks, np.asarray(energy)


@eqx.filter_jit
def autodiff_normal_modes(scene):
    """lagjax's normal modes of the scene's H, Legendre-transformed, about q = 0,
    and the scene's closed forms (frequencies, modes), in one compiled call."""
    q_eq = jnp.zeros_like(scene.initial_state()[0])
    omegas, modes = lj.normal_modes(scene.system().to_lagrangian(), q_eq, scene)
    return omegas, modes, scene.normal_mode_frequencies(), scene.normal_modes()


@pytest.mark.parametrize(
    "scene_class",
    oscillators.SCENES + driven.SCENES + pendulums.SCENES + chains.SCENES,
)
def test_scene_convention(scene_class):
    scene = scene_class()
    system = scene.system()
    if scene.state_kind == "momentum":
        assert isinstance(system, lj.SeparableHamiltonian)
    else:
        assert isinstance(system, lj.Lagrangian) and system.quadratic_in_velocity
    assert 0 < scene.default_dt < scene.default_t1
    # Parameters are array leaves: a batch of scenes is a vmappable pytree (compiled
    # whole, with the single scene's value: cheaper than dispatching op by op).
    at_start = lambda s: s.system()(*s.initial_state(), 0.0, s)

    @eqx.filter_jit
    def single_and_pair(scene):
        pair = jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), scene)
        return at_start(scene), jax.vmap(at_start)(pair)

    value, values = single_and_pair(scene)
    assert value.shape == () and np.isfinite(value)
    assert np.allclose(values, value, rtol=1e-14, atol=0)


@jax.jit
def harmonic_sweep(stiffnesses):
    """A vmapped sweep over stiffness, compiled whole with the scenes it builds: each
    scene's checks, and the angle each turned through (mod 2π) by the end."""
    scenes = jax.vmap(lambda k: HarmonicOscillator(stiffness=k))(stiffnesses)
    solver = lj.Yoshida6()
    trajectories, checks, _ = jax.vmap(
        lambda scene: compiled_checked_run(scene, solver, 0.01, 10.0, 1001, 1e-8)
    )(scenes)

    def turned(scene, q1, p1):
        return scene.angle(q1, p1) - scene.angle(*scene.initial_state())

    ends = trajectories.q[:, -1], trajectories.p[:, -1]
    return checks, jnp.mod(jax.vmap(turned)(scenes, *ends), 2 * jnp.pi)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_harmonic_oscillator_exact_solution_and_action_angle_over_a_sweep():
    # A vmapped sweep over stiffness: each scene's run against its own closed form.
    # Yoshida6 at ωh ≤ 0.03 over ≤ 10 periods: phase error ~ (ωh)⁶ωt ≈ 1e-9.
    stiffnesses = np.array([1.0, 4.0, 9.0])
    checks, turned = jax.tree_util.tree_map(np.asarray, harmonic_sweep(stiffnesses))
    assert set(checks) == {"q(t)", "p(t)", "action J", "angle advance φ(t) − φ(0)"}
    for index in range(len(stiffnesses)):
        one_scene = {name: (m[index], e[index]) for name, (m, e) in checks.items()}
        for name, error in worst_relative_errors(one_scene).items():
            assert error < 1e-8, (name, index, error)
    # The angle really advances at ω: over 10 s the ω = 3 scene turns 30 rad.
    assert np.isclose(turned[2], np.mod(30.0, 2 * np.pi), rtol=1e-9, atol=0)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_coupled_oscillators_general_and_diagonal_stiffness():
    general = CoupledOscillators()
    diagonal = CoupledOscillators(stiffness=(1.0, 4.0, 9.0))
    for scene in (general, diagonal):
        _, worst, _, _ = checked_run(scene, lj.Yoshida6(), 0.005, 20.0, 2001)
        for name, error in worst.items():
            assert error < 1e-8, (name, error)
        # The closed form against lagjax's autodiff normal modes of the same H.
        omegas, modes, frequencies, closed_modes = map(
            np.asarray, autodiff_normal_modes(scene)
        )
        assert np.allclose(omegas, frequencies, rtol=1e-12, atol=0)
        overlap = np.abs(modes.T @ np.diag(scene.masses) @ closed_modes)
        assert np.allclose(overlap, np.eye(3), rtol=0, atol=1e-10)
    expected = np.sort(np.sqrt(np.array([1.0, 4.0, 9.0]) / np.array(diagonal.masses)))
    assert np.allclose(frequencies, expected, rtol=1e-14, atol=0)  # the diagonal


def test_coupled_oscillators_reject_mismatched_stiffness():
    with pytest.raises(ValueError, match="stiffness must be"):
        CoupledOscillators(masses=(1.0, 2.0), stiffness=np.eye(3))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_driven_oscillator_transient_and_steady_state():
    # Adaptive Dopri8 at rtol = 1e-12 over 60 s = 14 drive periods; the response
    # is fitted after the transient has decayed by e^{-20}. t1 is traced so that
    # the next test reuses the compiled run.
    scene = DampedDrivenOscillator()
    t1 = jnp.asarray(60.0, dtype=float)  # not weakly typed, like the next test's
    trajectory, worst, _, _ = checked_run(
        scene, diffrax.Dopri8(), None, t1, 1201, 1e-12
    )
    for name, error in worst.items():
        assert error < 1e-8, (name, error)
    # The response itself: Ω = 1.5 below resonance ω₀ = 2, so q lags by δ < π/2.
    amplitude, lag = scene.measured_response(trajectory)
    assert np.isclose(amplitude, 1 / np.hypot(4 - 1.5**2, 1.5), rtol=1e-8, atol=0)
    assert np.isclose(lag, np.arctan2(1.5, 4 - 1.5**2), rtol=1e-8, atol=0)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_light_damping_energy_decays_as_exp_minus_gamma_t():
    # Free motion, γ = 0.05 ≪ ω₀ = 2. E e^{γt} has period π/ω_d, so between t = 0
    # and 40 half-periods the average decay rate is exactly γ.
    scene = DampedDrivenOscillator(damping=0.05, drive_amplitude=0.0)
    t1 = 40 * np.pi / scene.damped_frequency()
    # t1 traced: the same compiled run as the driven test.
    trajectory, checks, energy = compiled_checked_run(
        scene, diffrax.Dopri8(), None, t1, 1201, 1e-12
    )
    energy, ts = np.asarray(energy), np.asarray(trajectory.ts)
    rate = np.log(energy[0] / energy[-1]) / t1
    assert np.isclose(rate, 0.05, rtol=1e-8, atol=0)
    measured, expected = checks["energy decay rate"]
    assert np.isclose(measured, expected, rtol=1e-8, atol=0)
    assert np.isclose(expected, 0.05, rtol=1e-12, atol=0)
    # Within a half-period E is not a pure exponential: it wiggles about it.
    wiggle = energy * np.exp(0.05 * ts) / energy[0]
    assert 1e-3 < np.ptp(wiggle) < 0.1


def test_a_free_damped_run_judges_no_steady_state_phase():
    # No drive: the steady state has amplitude 0 and no phase; the other checks
    # still hold against the closed form.
    scene = lj.scenes.DampedDrivenOscillator(drive_amplitude=0.0)
    ts = jnp.linspace(0.0, 60.0, 601)
    run = lj.simulate(scene, scene.initial_state(), t1=60.0, ts=ts)
    checks = scene.checks(run)
    assert "steady-state phase" not in checks
    measured, exact = checks["q(t)"]
    np.testing.assert_allclose(measured, exact, atol=1e-6)
    amplitude, expected = checks["steady-state amplitude"]
    assert float(expected) == 0.0 and abs(float(amplitude)) < 1e-6
