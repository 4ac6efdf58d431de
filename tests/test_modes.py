"""Normal modes and equilibria against the course text's closed forms (§5)."""

import jax.numpy as jnp
import numpy as np

import lagjax as lj
from tests.helpers import relative_close


def co2(eta, eta_dot, t, args):
    # Course text eq. (5.36)–(5.38): masses m, M, m joined by springs k.
    m, big_m, k = args
    masses = jnp.array([m, big_m, m])
    return 0.5 * jnp.sum(masses * eta_dot**2) - 0.5 * k * (
        (eta[1] - eta[0]) ** 2 + (eta[2] - eta[1]) ** 2
    )


def test_co2_frequencies_and_mode_shapes():
    m, big_m, k = 16.0, 12.0, 3.0
    lag = lj.Lagrangian(co2)
    omegas, modes = lj.normal_modes(lag, jnp.zeros(3), (m, big_m, k))
    expected = np.array([0.0, np.sqrt(k / m), np.sqrt(k / m * (1 + 2 * m / big_m))])
    # The translation mode's ω = √(round-off in ω²) is only ~1e-8 from zero.
    assert abs(float(omegas[0])) < 1e-7
    assert relative_close(omegas[1:], expected[1:], 1e-10)
    # Translation (1, 1, 1); symmetric stretch (1, 0, −1); asymmetric
    # stretch (1, −2m/M, 1) — the course text's eigenvectors.
    shapes = [
        np.array([1, 1, 1]),
        np.array([1, 0, -1]),
        np.array([1, -2 * m / big_m, 1]),
    ]
    for column, shape in zip(modes.T, shapes):
        cosine = abs(column @ shape) / (np.linalg.norm(column) * np.linalg.norm(shape))
        assert relative_close(cosine, 1.0, 1e-10)
    T = np.diag([m, big_m, m])
    assert np.allclose(modes.T @ T @ modes, np.eye(3), atol=1e-12)


def test_double_pendulum_frequencies():
    g, length = 9.81, 0.7

    def L(q, qd):
        kinetic = length**2 * (
            qd[0] ** 2 + 0.5 * qd[1] ** 2 + qd[0] * qd[1] * jnp.cos(q[0] - q[1])
        )
        return kinetic + g * length * (2 * jnp.cos(q[0]) + jnp.cos(q[1]))

    omegas, modes = lj.normal_modes(lj.Lagrangian(L), jnp.zeros(2))
    expected = np.sqrt(np.array([2 - np.sqrt(2), 2 + np.sqrt(2)]) * g / length)
    assert relative_close(omegas, expected, 1e-12)
    # Mode shapes: θ2/θ1 = ±√2 (in phase for the slow mode).
    assert relative_close(modes[1, 0] / modes[0, 0], np.sqrt(2), 1e-10)
    assert relative_close(modes[1, 1] / modes[0, 1], -np.sqrt(2), 1e-10)


def test_equilibrium_of_tilted_pendulum():
    # V = −g cos θ − F θ: equilibrium at sin θ = F/g.
    g, F = 9.81, 2.5
    lag = lj.Lagrangian(lambda th, thd: 0.5 * thd**2 + g * jnp.cos(th) + F * th)
    theta = lj.equilibrium(lag, 0.1)
    assert relative_close(np.sin(theta), F / g, 1e-12)
    omegas, _ = lj.normal_modes(lag, theta)
    assert relative_close(omegas[0] ** 2, g * np.cos(theta), 1e-10)


def test_unstable_equilibrium_reports_growth_rate():
    g = 9.81
    lag = lj.Lagrangian(lambda th, thd: 0.5 * thd**2 + g * jnp.cos(th))
    omegas, _ = lj.normal_modes(lag, jnp.pi)
    assert relative_close(omegas[0], -np.sqrt(g), 1e-12)
