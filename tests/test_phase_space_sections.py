"""Poincaré sections: crossings on the known curves, at the closed-form times."""

import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.phase_space import plot_poincare_section
from lagjax.special_functions import complete_elliptic_k

OMEGA_X, OMEGA_Y = 1.0, np.sqrt(2.0)
# Two uncoupled oscillators: every crossing of x = 0 upward lies on the ellipse
# ½(p_y² + ω_y² y²) = E_y, with p_x = ω_x A, at the times ω_x t = π/2 + 2πk.
OSCILLATORS = lj.SeparableHamiltonian(
    lambda p: 0.5 * (p[0] ** 2 + p[1] ** 2),
    lambda q: 0.5 * (OMEGA_X**2 * q[0] ** 2 + OMEGA_Y**2 * q[1] ** 2),
)
AMPLITUDES = jnp.array([1.0, 0.5])
Y0, PY0 = jnp.array([0.3, 0.7]), jnp.array([0.2, -0.1])
# x = −A cos(ω_x t): the first upward crossing is at ω_x t = π/2.
STATES = (jnp.stack([-AMPLITUDES, Y0], 1), jnp.stack([0 * Y0, PY0], 1))


SOLVER = lj.Yoshida4()


def plane_x(q, p):
    return q[0]


def _oscillator_section(direction=+1, max_crossings=5):
    return lj.poincare_section(
        OSCILLATORS, STATES, 40.0, plane_x, direction=direction, dt=0.01,
        solver=SOLVER, max_crossings=max_crossings,
    )  # fmt: skip


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_crossings_lie_on_the_invariant_ellipse_at_the_closed_form_times():
    section = _oscillator_section()
    # 7 crossings before t = 40; the first 5 are stored, all are counted.
    np.testing.assert_array_equal(section.count, [7, 7])
    assert section.ts.shape == (2, 5)
    exact = np.tile((np.pi / 2 + 2 * np.pi * np.arange(5)) / OMEGA_X, (2, 1))
    # Yoshida4 at h = 0.01 runs the oscillator at a frequency off by ~7e-10
    # (O(h⁴)): the located times carry that phase error, growing with t, and no more.
    np.testing.assert_allclose(section.ts, exact, rtol=1e-9, atol=0)
    # Hénon's step lands on the surface to round-off, not to the step's accuracy.
    assert np.max(np.abs(section.q[..., 0])) < 1e-14
    energy_y = 0.5 * (section.p[..., 1] ** 2 + OMEGA_Y**2 * section.q[..., 1] ** 2)
    expected = 0.5 * (PY0**2 + OMEGA_Y**2 * Y0**2)
    np.testing.assert_allclose(energy_y, np.tile(expected[:, None], 5), atol=1e-11)
    np.testing.assert_allclose(
        section.p[..., 0], np.tile((OMEGA_X * AMPLITUDES)[:, None], 5), atol=1e-11
    )


@pytest.mark.integration  # a long run; CI runs it in its integration step (default-suite time)
def test_both_directions_alternate_and_pad_with_nan():
    both = _oscillator_section(direction=0, max_crossings=16)
    # Upward at ω_x t = π/2 + 2πk, downward at 3π/2 + 2πk: 13 before t = 40.
    np.testing.assert_array_equal(both.count, [13, 13])
    exact = (0.5 * np.pi + np.pi * np.arange(13)) / OMEGA_X
    np.testing.assert_allclose(both.ts[:, :13], np.tile(exact, (2, 1)), rtol=1e-9)
    signs = np.sign(both.p[:, :13, 0])
    np.testing.assert_array_equal(signs, np.tile((-1.0) ** np.arange(13), (2, 1)))
    assert np.all(np.isnan(both.ts[:, 13:])) and np.all(np.isnan(both.q[:, 13:]))
    assert np.all(np.isnan(both.p[:, 13:]))


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_lagrangian_pendulum_crosses_at_three_quarter_periods():
    # From rest at θ0 the pendulum passes θ = 0 upward at 3T/4 + kT, with
    # T = 4K(sin²(θ0/2)) and momentum √(2(1 − cos θ0)).
    theta0 = 1.2
    pendulum = lj.Lagrangian(lambda q, qdot: 0.5 * qdot**2 + jnp.cos(q))
    states = (jnp.asarray([theta0]), jnp.asarray([0.0]))
    section = lj.poincare_section(
        pendulum, states, 30.0, lambda q, p: q, dt=0.01, max_crossings=8
    )
    period = 4 * float(complete_elliptic_k(np.sin(theta0 / 2) ** 2))
    count = int(section.count[0])
    assert count == int((30.0 - 0.75 * period) // period) + 1
    expected = 0.75 * period + period * np.arange(count)
    np.testing.assert_allclose(section.ts[0, :count], expected, atol=1e-9)
    np.testing.assert_allclose(
        section.p[0, :count], np.sqrt(2 * (1 - np.cos(theta0))), atol=1e-10
    )


@pytest.mark.integration  # a long run; CI runs it in its integration step (default-suite time)
def test_plot_draws_every_stored_crossing():
    import matplotlib

    matplotlib.use("Agg")
    ax, section = plot_poincare_section(
        OSCILLATORS, STATES, 40.0, plane_x, dt=0.01, solver=SOLVER,
        max_crossings=5, horizontal=lambda q, p: q[1], vertical=lambda q, p: p[1],
    )  # fmt: skip
    drawn = [np.asarray(collection.get_offsets()) for collection in ax.collections]
    assert [len(points) for points in drawn] == [5, 5]  # one scatter per orbit
    np.testing.assert_allclose(drawn[0][:, 0], section.q[0, :, 1])
    np.testing.assert_allclose(drawn[1][:, 1], section.p[1, :, 1])


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="direction"):
        lj.poincare_section(OSCILLATORS, STATES, 1.0, lambda q, p: q[0], dt=0.1,
                            direction=2)  # fmt: skip
    with pytest.raises(ValueError, match="fixed dt"):
        lj.poincare_section(OSCILLATORS, STATES, 1.0, lambda q, p: q[0], dt=None)
    with pytest.raises(ValueError, match="max_crossings"):
        lj.poincare_section(OSCILLATORS, STATES, 1.0, lambda q, p: q[0], dt=0.1,
                            max_crossings=0)  # fmt: skip


def test_states_on_energy_shell_have_the_energy():
    q = jnp.array([[0.0, 0.1], [0.0, 0.9], [0.0, -0.2]])
    p = jnp.array([[0.0, 0.1], [0.0, 0.0], [5.0, -0.3]])
    kept_q, kept_p = lj.states_on_energy_shell(OSCILLATORS, 0.125, (q, p), 0)
    assert kept_q.shape == (2, 2)  # y = 0.9 has V > E: outside the shell
    energies = [OSCILLATORS(a, b) for a, b in zip(kept_q, kept_p, strict=True)]
    np.testing.assert_allclose(energies, 0.125, rtol=1e-13)
    assert np.all(kept_p[:, 0] >= 0)
