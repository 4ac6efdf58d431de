"""Normal modes and equilibria against the course text's closed forms (§5)."""

import jax.numpy as jnp
import numpy as np
import pytest

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


def test_modes_are_classified_and_unpack_from_a_result():
    m, big_m, k = 16.0, 12.0, 3.0
    result = lj.normal_modes(lj.Lagrangian(co2), jnp.zeros(3), (m, big_m, k))
    # The free translation is neutral; the two stretches oscillate.
    assert result.labels() == ("marginal", "stable", "stable")
    assert result.verdict() == "marginal" and not result.gyroscopic
    assert np.allclose(result.eigenvalues[1:], 1j * result.omegas[1:], rtol=1e-14)
    omegas, modes = result
    assert omegas is result.omegas and modes is result.modes


def test_first_order_path_agrees_with_the_closed_form_without_gyroscopic_terms():
    g, length = 9.81, 0.7

    def L(q, qd):
        kinetic = length**2 * (
            qd[0] ** 2 + 0.5 * qd[1] ** 2 + qd[0] * qd[1] * jnp.cos(q[0] - q[1])
        )
        return kinetic + g * length * (2 * jnp.cos(q[0]) + jnp.cos(q[1]))

    result = lj.normal_modes(lj.Lagrangian(L), jnp.zeros(2), gyroscopic=True)
    expected = np.sqrt(np.array([2 - np.sqrt(2), 2 + np.sqrt(2)]) * g / length)
    assert result.gyroscopic and relative_close(result.omegas, expected, 1e-12)
    # Without G the complex shapes are real up to the phase fixed by the
    # normalisation: θ2/θ1 = ±√2 again.
    ratio = np.asarray(result.modes[1] / result.modes[0])
    assert relative_close(ratio, [np.sqrt(2), -np.sqrt(2)], 1e-10)
    assert np.max(np.abs(np.asarray(result.modes).imag)) < 1e-12


def test_a_point_that_is_not_an_equilibrium_is_refused():
    # Tilted pendulum: at θ = 0 the constant force F is unbalanced.
    g, F = 9.81, 2.5
    lag = lj.Lagrangian(lambda th, thd: 0.5 * thd**2 + g * jnp.cos(th) + F * th)
    with pytest.raises(ValueError, match=r"residual generalized force .* \[2\.5\]"):
        lj.normal_modes(lag, 0.0)
    # Opting out expands about the point anyway: ω² = g cos 0.
    omegas, _ = lj.normal_modes(lag, 0.0, check_equilibrium=False)
    assert relative_close(omegas, np.sqrt(g), 1e-12)


def test_cartesian_pendulum_modes_live_on_its_rod():
    # (x, y) with √(x² + y²) = l: one mode, ω = √(g/l), along the circle's tangent.
    g, length, mass = 9.81, 0.7, 2.0
    lag = lj.Lagrangian(
        lambda q, qd: 0.5 * mass * jnp.sum(qd**2) - mass * g * q[1],
        constraints=lambda q: jnp.sqrt(q[0] ** 2 + q[1] ** 2) - length,
    )
    omegas, modes = lj.normal_modes(lag, jnp.array([0.0, -length]))
    assert modes.shape == (2, 1)
    assert relative_close(omegas, np.sqrt(g / length), 1e-12)
    assert relative_close(np.abs(modes[:, 0]), [mass**-0.5, 0.0], 1e-12)  # aᵀMa = 1
    # Off the rod is refused, naming the constraint residual.
    with pytest.raises(ValueError, match="constraint residual"):
        lj.normal_modes(lag, jnp.array([0.0, -1.1 * length]))


def test_velocity_constraints_are_pointed_to_linearize():
    lag = lj.Lagrangian(
        lambda q, qd: 0.5 * jnp.sum(qd**2),
        constraints=lj.Constraints(velocity=lambda q, qd: qd[0] - q[1] * qd[1]),
    )
    with pytest.raises(ValueError, match="linearize"):
        lj.normal_modes(lag, jnp.zeros(2))
