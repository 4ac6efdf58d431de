"""Chains of masses and springs against their closed forms (lagjax/scenes/chains.py).

Each run is compiled together with everything the test reads from it (the scene's
checks, normal coordinates, oscillatory energies): run eagerly, those are dozens of
small operations, each compiled on its own.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.scenes.chains import (
    FermiPastaUlamChain,
    LinearTriatomicMolecule,
    SpringChain,
)

SPEED_OF_LIGHT_CM = 2.99792458e10  # cm/s, for wavenumbers


@eqx.filter_jit
def run_saved(scene, y0, solver, dt, t1, samples, measure=None):
    """Fixed steps from y0 (None: the scene's initial state), saved at equally
    spaced times that fall on steps; returns the run, the scene's checks of it and
    `measure(scene, y0, run)`."""
    y0 = scene.initial_state() if y0 is None else y0
    ts = jnp.linspace(0.0, t1, samples)
    run = lj.simulate(scene, y0, t1=t1, dt=dt, solver=solver, ts=ts)
    return run, scene.checks(run), None if measure is None else measure(scene, y0, run)


@eqx.filter_jit
def autodiff_small_oscillations(scene):
    """lagjax's (ω, A) and (T, V) for the scene's H, Legendre-transformed, at q = 0."""
    lagrangian = scene.system().to_lagrangian()
    q_eq = jnp.zeros_like(scene.initial_state()[0])
    omegas, modes = lj.normal_modes(lagrangian, q_eq, scene)
    return omegas, modes, lj.stiffness_matrices(lagrangian, q_eq, scene)


@eqx.filter_jit
def closed_forms(scene):
    """The scene's closed-form frequencies ω and modes A (mode k in column k)."""
    return scene.normal_mode_frequencies(), scene.normal_modes()


def as_numpy(tree):
    return jax.tree.map(np.asarray, tree)


def test_co2_frequencies_and_mode_shapes_of_the_course_text():
    scene = LinearTriatomicMolecule()
    expected, closed = as_numpy(closed_forms(scene))
    omegas, modes, (kinetic, potential) = as_numpy(autodiff_small_oscillations(scene))
    assert np.allclose(omegas, expected, rtol=1e-10, atol=1e-7 * expected[-1])
    # Eq. 5.47–5.51 solve the secular problem V a = ω² T a with Aᵀ T A = 1 ...
    scale = np.max(np.abs(potential @ closed))
    secular = potential @ closed - kinetic @ closed * expected**2
    assert np.max(np.abs(secular)) < 1e-12 * scale
    assert np.allclose(closed.T @ kinetic @ closed, np.eye(3), rtol=0, atol=1e-12)
    # ... and agree with lagjax's modes, column by column, up to sign.
    assert np.allclose(np.abs(modes.T @ kinetic @ closed), np.eye(3), rtol=0, atol=1e-9)
    # Translation, symmetric stretch (carbon still), asymmetric stretch.
    assert np.allclose(closed[:, 0], closed[0, 0]) and closed[1, 1] == 0
    m, big_m = float(scene.outer_mass), float(scene.central_mass)
    assert np.isclose(closed[1, 2] / closed[0, 2], -2 * m / big_m, rtol=1e-14, atol=0)
    # The docstring's wavenumbers: 1335 and 2556 cm⁻¹ for k = 1680 N/m.
    wavenumbers = expected[1:] / (2 * np.pi * SPEED_OF_LIGHT_CM)
    assert np.allclose(wavenumbers, [1335, 2556], atol=1.0)


def co2_coordinates(scene, start, run):
    """ξ(t), ξ at the start, and the masses (m, M, m)."""
    return (
        scene.normal_coordinates(run.q),
        scene.normal_coordinates(start[0]),
        scene.masses(),
    )


co2_mode_state = eqx.filter_jit(LinearTriatomicMolecule.mode_state)


@pytest.mark.integration  # a long run; CI runs it in its integration step (default-suite time)
def test_co2_motion_started_in_a_mode_stays_in_it():
    # Yoshida6 at ω₃h = 0.024 over 0.5 ps ≈ 38 periods of the asymmetric stretch.
    scene = LinearTriatomicMolecule()
    omegas = np.asarray(closed_forms(scene)[0])
    for mode in (1, 2):
        start = co2_mode_state(scene, mode)
        run, checks, measured = run_saved(
            scene, start, lj.Yoshida6(), 5e-17, 5e-13, 1001, co2_coordinates
        )
        xi, start_xi, masses = as_numpy(measured)
        amplitude = start_xi[mode]
        expected = amplitude * np.cos(omegas[mode] * np.asarray(run.ts))
        assert np.max(np.abs(xi[:, mode] - expected)) < 1e-8 * abs(amplitude)
        others = np.delete(xi, mode, axis=1)
        assert np.max(np.abs(others)) < 1e-12 * abs(amplitude)
        # Both stretches leave the centre of mass where it was (here 0).
        centre = np.asarray(run.q) @ masses / masses.sum()
        assert np.max(np.abs(centre)) < 1e-13 * np.max(np.abs(np.asarray(start[0])))
    checks = as_numpy(checks)  # the last run started from initial_state()
    assert checks["leakage out of the asymmetric stretch"][0] < 1e-12
    measured, exact = checks["η(t)"]
    assert np.max(np.abs(measured - exact)) < 1e-8 * np.max(np.abs(exact))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_spring_chain_modes_and_exact_motion():
    scene = SpringChain()
    omegas, modes, (kinetic, _) = as_numpy(autodiff_small_oscillations(scene))
    closed_omegas, closed = as_numpy(closed_forms(scene))
    assert np.allclose(omegas, closed_omegas, rtol=1e-12, atol=0)
    assert np.allclose(
        np.abs(modes.T @ kinetic @ closed), np.eye(8), rtol=0, atol=1e-10
    )
    # Yoshida6 at ω_max h ≈ 0.05 over 10 s; every mode is excited.
    _, checks, _ = run_saved(scene, None, lj.Yoshida6(), 0.0025, 10.0, 1001)
    for name, (measured, expected) in as_numpy(checks).items():
        error = np.max(np.abs(measured - expected)) / np.max(np.abs(expected))
        assert error < 1e-8, (name, error)


def oscillatory_energies(scene, start, run):
    """I_j(t) of each stiff spring and their sum I(t)."""
    each = scene.oscillatory_energies(run.q, run.p)
    return each, jnp.sum(each, axis=-1)


@pytest.mark.integration  # compile-heavy (10–15 s): CI runs it in its integration step
def test_fermi_pasta_ulam_stiff_springs_trade_energy_but_keep_its_sum():
    # A near-exact run (Yoshida6, ωh = 0.25; H kept to 5e-7) shows HLW's
    # Fig. I.5.2: by t = 150 the first stiff spring has handed nearly all its
    # energy to the third, while I = ΣI_j stays within O(1/ω) of I(0) = 1.
    scene = FermiPastaUlamChain()
    _, checks, energies = run_saved(
        scene, None, lj.Yoshida6(), 0.005, 200.0, 2001, oscillatory_energies
    )
    each, total = as_numpy(energies)
    at_150 = each[1500]
    assert at_150[0] < 0.05 and at_150[2] > 0.9
    assert np.isclose(total[0], 1.0, rtol=1e-12, atol=0)
    assert np.max(np.abs(total - 1)) < 4 / float(scene.frequency)  # measured 0.062
    energy, start_energy = as_numpy(checks)["energy"]
    assert np.max(np.abs(energy - start_energy)) < 1e-6 * abs(start_energy[0])


def test_fermi_pasta_ulam_oscillatory_energy_with_stormer_verlet_at_omega_h_1():
    # Störmer–Verlet at ωh = 1 over 1000 time units (5·10⁴ steps): I oscillates
    # about a shifted mean with a bounded amplitude (measured max |I − 1| = 0.22,
    # mean offset +0.021) and does not drift (mean of the first and the last
    # tenth agree to 2e-4).
    scene = FermiPastaUlamChain()
    _, checks, energies = run_saved(
        scene, None, lj.StormerVerlet(), 0.02, 1000.0, 10001, oscillatory_energies
    )
    total = np.asarray(energies[1])
    assert np.max(np.abs(total - 1)) < 0.25
    tenth = len(total) // 10
    assert abs(total[-tenth:].mean() - total[:tenth].mean()) < 1e-3
    measured, expected = as_numpy(checks)["oscillatory energy I"]
    assert np.allclose(measured, total) and np.allclose(expected, 1.0)
