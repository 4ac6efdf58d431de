"""MEGNO and FLI: 0 for isochronous, 2 for quasi-periodic, λt/2 for chaotic orbits."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.phase_space import henon_heiles, henon_heiles_section_states

PENDULUM = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: -jnp.cos(q))
OSCILLATOR = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: 0.5 * q**2)
OPTIONS = dict(dt=0.05, solver=lj.Yoshida4(), renormalize_every=0.5)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_megno_of_a_libration_approaches_two():
    y0 = (jnp.asarray(2.0), jnp.asarray(0.0))
    early = lj.megno(PENDULUM, y0, 500.0, **OPTIONS)
    late = lj.megno(PENDULUM, y0, 2000.0, **OPTIONS)
    # Shear makes the deviation grow linearly: ⟨Y⟩ = 2 − O(ln t / t) from below.
    assert 1.5 < early < late < 2.0
    assert late > 1.85
    assert abs(late - 2) < 0.6 * abs(early - 2)


def test_megno_of_the_isochronous_oscillator_vanishes():
    # No shear: the deviation only rotates, ln‖δ‖ stays bounded and ⟨Y⟩ → 0 as 1/t.
    indicators = lj.chaos_indicators(
        OSCILLATOR, (jnp.asarray(1.0), jnp.asarray(0.0)), 1000.0, **OPTIONS
    )
    assert abs(indicators.megno) < 0.01
    assert abs(indicators.fli) < 1e-6  # ‖δ‖ = 1 throughout: a rotation


def test_henon_heiles_chaotic_orbit_megno_grows_as_lambda_t_over_two():
    states = henon_heiles_section_states(1 / 6, [-0.1], [0.0])
    regular = henon_heiles_section_states(1 / 12, [0.1], [0.0])
    pick = jax.tree_util.tree_map(lambda x: jnp.asarray(x[0]), (states, regular))
    chaotic = lj.chaos_indicators(henon_heiles(), pick[0], 1000.0, **OPTIONS)
    calm = lj.chaos_indicators(henon_heiles(), pick[1], 1000.0, **OPTIONS)
    assert chaotic.megno > 20
    # ⟨Y⟩ ≈ λt/2 with the orbit's own finite-time exponent.
    np.testing.assert_allclose(chaotic.megno, chaotic.lyapunov * 1000.0 / 2, rtol=0.2)
    assert abs(calm.megno - 2) < 0.2
    assert chaotic.fli > calm.fli + 50


def test_indicators_vmap_over_a_grid():
    y0s = (jnp.linspace(0.5, 2.5, 4), jnp.zeros(4))

    def one(q, p):
        return lj.megno(PENDULUM, (q, p), 50.0, **OPTIONS)

    mapped = jax.vmap(one)(*y0s)
    singles = [one(q, p) for q, p in zip(*y0s, strict=True)]
    np.testing.assert_allclose(mapped, singles, rtol=1e-12)


def test_bad_deviation_is_named():
    with pytest.raises(ValueError, match="deviation must be a flat vector"):
        lj.megno(PENDULUM, (jnp.asarray(1.0), jnp.asarray(0.0)), 5.0,
                 deviation=jnp.ones(3), **OPTIONS)  # fmt: skip
