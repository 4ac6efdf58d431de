"""Lyapunov spectra: exact exponents of a linear saddle, Hamiltonian pairing, zero sum."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.phase_space import henon_heiles, henon_heiles_section_states

# H = ½|p|² − ½x² + ½ω²y²: a saddle times a centre. At the equilibrium the tangent
# flow is exp(At), whose exponents are the real parts of A's eigenvalues ±1, ±iω.
SADDLE_CENTRE = lj.SeparableHamiltonian(
    lambda p: 0.5 * (p[0] ** 2 + p[1] ** 2),
    lambda q: -0.5 * q[0] ** 2 + 0.5 * 1.3**2 * q[1] ** 2,
)


def test_saddle_centre_exponents_are_the_eigenvalues_real_parts():
    spectrum = lj.lyapunov_spectrum(
        SADDLE_CENTRE, (jnp.zeros(2), jnp.zeros(2)), 200.0, dt=0.05,
        solver=lj.Yoshida4(), renormalize_every=0.5,
    )  # fmt: skip
    # The QR estimate converges as O(1/t): ln of the basis' initial projection / t.
    np.testing.assert_allclose(spectrum.exponents, [1.0, 0.0, 0.0, -1.0], atol=5e-3)
    assert spectrum.running.shape == (400, 4)
    np.testing.assert_allclose(spectrum.ts[-1], 200.0)
    # Symplectic solver: det of every tangent map is 1, the sum vanishes throughout.
    assert np.max(np.abs(spectrum.running.sum(axis=1))) < 1e-12


def test_chaotic_henon_heiles_orbit_has_paired_spectrum_summing_to_zero():
    states = henon_heiles_section_states(1 / 6, [-0.1], [0.0])
    y0 = jax.tree_util.tree_map(lambda x: jnp.asarray(x[0]), states)
    spectrum = lj.lyapunov_spectrum(
        henon_heiles(), y0, 1000.0, dt=0.05, solver=lj.Yoshida4(),
        renormalize_every=0.5,
    )  # fmt: skip
    largest, second, third, smallest = np.asarray(spectrum.exponents)
    assert largest > 0.05  # chaotic (≈0.15 over this short horizon)
    assert largest >= second >= third >= smallest
    # Two near-zero exponents (along the flow and across the energy shell) and a
    # ± pair; both hold to O(1/t) — about 4/t for this orbit, so t = 1000 leaves
    # room for round-off, which on a chaotic orbit changes which part of the sea is
    # sampled (t = 500 gave 0.008 on jax 0.10 and 0.0101 on jax 0.11).
    assert abs(second) < 0.01 and abs(third) < 0.01
    assert abs(largest + smallest) < 0.01
    assert np.max(np.abs(spectrum.running.sum(axis=1))) < 1e-12


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_adaptive_and_fixed_step_spectra_agree_on_a_lagrangian_orbit():
    # The finite-time spectrum belongs to the orbit and the initial basis, not the
    # integrator: Tsit5 (adaptive, differentiated with ForwardMode) and GaussLegendre
    # (fixed step, through the Legendre transform) must give the same numbers.
    pendulum = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))
    y0 = (jnp.asarray(1.0), jnp.asarray(0.0))
    adaptive = lj.lyapunov_spectrum(
        pendulum, y0, 20.0, renormalize_every=1.0, rtol=1e-12, atol=1e-12
    )
    fixed = lj.lyapunov_spectrum(pendulum, y0, 20.0, dt=0.01, renormalize_every=1.0)
    np.testing.assert_allclose(adaptive.running, fixed.running, atol=1e-8)
    # A regular orbit: the tangent vectors grow linearly, so λ(t) ~ ln t / t.
    assert np.max(np.abs(fixed.exponents)) < 2 * np.log(20.0) / 20.0
    np.testing.assert_allclose(fixed.running.sum(axis=1), 0.0, atol=1e-12)


@pytest.mark.slow
def test_henon_heiles_spectrum_converges_at_e_one_sixth():
    states = henon_heiles_section_states(1 / 6, [-0.1], [0.0])
    y0 = jax.tree_util.tree_map(lambda x: jnp.asarray(x[0]), states)
    spectrum = lj.lyapunov_spectrum(
        henon_heiles(), y0, 40_000.0, dt=0.05, solver=lj.Yoshida4(),
        renormalize_every=1.0,
    )  # fmt: skip
    largest, second, third, smallest = np.asarray(spectrum.exponents)
    assert 0.05 < largest < 0.15
    assert abs(second) < 1e-3 and abs(third) < 1e-3
    assert abs(largest + smallest) < 1e-3


def test_bad_input_is_named():
    y0 = (jnp.zeros(2), jnp.zeros(2))
    with pytest.raises(ValueError, match="whole multiple of renormalize_every"):
        lj.lyapunov_spectrum(SADDLE_CENTRE, y0, 1.0, dt=0.1, renormalize_every=0.3)
    with pytest.raises(ValueError, match="whole multiple of dt"):
        lj.lyapunov_spectrum(SADDLE_CENTRE, y0, 1.0, dt=0.1, renormalize_every=0.25)
    with pytest.raises(ValueError, match="basis must be"):
        lj.lyapunov_spectrum(SADDLE_CENTRE, y0, 1.0, dt=0.1, basis=jnp.eye(3))
    with pytest.raises(ValueError, match=r"pair \(q0, qdot0\)"):
        lj.lyapunov_spectrum(SADDLE_CENTRE, jnp.zeros(4), 1.0, dt=0.1)
    with pytest.raises(ValueError, match="dt must be a finite positive"):
        lj.lyapunov_spectrum(SADDLE_CENTRE, y0, 1.0, dt=-0.1)
