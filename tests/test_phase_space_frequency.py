"""Frequency analysis: the pendulum's frequency against its elliptic closed form."""

import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.special_functions import complete_elliptic_k

PENDULUM = lj.SeparableHamiltonian(lambda p: 0.5 * p**2, lambda q: -jnp.cos(q))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_pendulum_libration_frequency_matches_the_elliptic_integral():
    theta0 = 1.0
    # ω = π ω0 / (2 K(k²)), k = sin(θ0/2), ω0 = 1.
    exact = np.pi / (2 * float(complete_elliptic_k(np.sin(theta0 / 2) ** 2)))
    ts = jnp.linspace(0.0, 400.0, 8001)
    run = lj.simulate(PENDULUM, (jnp.asarray(theta0), jnp.asarray(0.0)), 0.0, 400.0,
                      dt=0.01, solver=lj.KahanLi8(), ts=ts)  # fmt: skip
    found = lj.fundamental_frequencies(run.ts, run.q, terms=2)
    np.testing.assert_allclose(found.omegas[0], exact, rtol=1e-10)
    # θ(t) is odd-harmonic: the next term is at 3ω.
    np.testing.assert_allclose(found.omegas[1], 3 * exact, rtol=1e-9)
    # q − i p turns clockwise: its leading frequency is +ω.
    rotating = lj.fundamental_frequencies(run.ts, run.q - 1j * run.p, terms=1)
    np.testing.assert_allclose(rotating.omegas[0], exact, rtol=1e-10)


def test_two_term_signal_frequencies_and_amplitudes():
    ts = jnp.linspace(0.0, 100.0, 2001)
    signal = 0.7 * jnp.cos(1.234567 * ts + 0.3) + 0.2 * jnp.sin(3.3 * ts) + 0.05
    found = lj.fundamental_frequencies(ts, signal, terms=2)
    np.testing.assert_allclose(found.omegas, [1.234567, 3.3], rtol=1e-9)
    # A real term a e^{iωt} + conj has amplitude 2|a| and phase arg a.
    np.testing.assert_allclose(2 * jnp.abs(found.amplitudes), [0.7, 0.2], rtol=1e-8)
    np.testing.assert_allclose(jnp.angle(found.amplitudes[0]), 0.3, atol=1e-8)


def test_bad_samples_are_named():
    ts = jnp.linspace(0.0, 1.0, 20)
    with pytest.raises(ValueError, match="same length"):
        lj.fundamental_frequencies(ts, jnp.zeros(19))
    with pytest.raises(ValueError, match="equally spaced"):
        lj.fundamental_frequencies(ts**2, jnp.zeros(20))
    with pytest.raises(ValueError, match="terms must be"):
        lj.fundamental_frequencies(ts, jnp.zeros(20), terms=0)
