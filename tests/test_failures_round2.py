"""Catalogue of bad or extreme input, round two: runs that must return, declared
structure that must be checked, time and precision that must be kept, and refusals
that must name the problem and the remedy.

Each case asserts a clear refusal (its message names the problem and what to do) or
the right answer against a closed form.
"""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.mechanics.legendre import invert_gradient

# -- A run that returns ----------------------------------------------------------

MASS, LIGHT, FIELD = 1.5, 2.0, 0.8  # the relativistic particle of issue 33


def relativistic_in_field(q, qd):
    return -MASS * LIGHT**2 * jnp.sqrt(1 - qd @ qd / LIGHT**2) + MASS * FIELD * q[0]


def relativistic_closed_form(t, vy0):
    """(x, y) from rest along x, v_y = vy0 at t = 0: p_x = m a t, p_y constant."""
    p_y = MASS * vy0 / np.sqrt(1 - vy0**2 / LIGHT**2)
    rest = np.sqrt(MASS**2 * LIGHT**4 + LIGHT**2 * p_y**2)
    energy = np.sqrt(rest**2 + (LIGHT * MASS * FIELD * t) ** 2)
    x = (energy - rest) / (MASS * FIELD)
    y = p_y * LIGHT / (MASS * FIELD) * np.arcsinh(MASS * FIELD * LIGHT * t / rest)
    return np.array([x, y])


def test_legendre_inverse_stops_once_converged():
    # Near the solution the merit's decrease is below its round-off; the damped
    # Newton used to halve ~20 times per iteration and run all 100 iterations
    # (thousands of evaluations of L per call; a 30-step run never returned).
    calls = []

    def kinetic(v):
        jax.debug.callback(lambda: calls.append(1))
        return -MASS * LIGHT**2 * jnp.sqrt(1 - v @ v / LIGHT**2)

    velocity = jnp.array([1.5, 0.3])  # 1810 evaluations before, 45 now
    momentum = jax.grad(kinetic)(velocity)
    calls.clear()
    found = jax.jit(
        lambda p: invert_gradient(kinetic, p, quadratic=False, what="∂²L/∂q̇²")
    )(momentum)
    jax.effects_barrier()
    np.testing.assert_allclose(found, velocity, rtol=1e-14)
    assert len(calls) < 100, len(calls)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_relativistic_particle_gauss_legendre_3_returns_the_closed_form():
    y0 = (jnp.array([0.0, 0.0]), jnp.array([0.0, 1.2]))
    trajectory = lj.simulate(
        lj.Lagrangian(relativistic_in_field), y0, t0=0.0, t1=0.3, dt=0.01,
        solver=lj.GaussLegendre(stages=3),
    )  # fmt: skip
    assert trajectory.result == diffrax.RESULTS.successful
    np.testing.assert_allclose(
        trajectory.q[-1], relativistic_closed_form(0.3, 1.2), rtol=1e-12
    )


# -- Declared structure, checked -------------------------------------------------


def relativistic_kinetic(p):
    return jnp.sqrt(1 + p**2)


def half_square(q):
    return 0.5 * q**2


def test_separable_relativistic_kinetic_is_not_taken_for_quadratic():
    # H = √(1 + p²) + q²/2: q̈ = −q (1 − q̇²)^{3/2} = −0.1536 at (0.3, 0.6).
    system = lj.SeparableHamiltonian(relativistic_kinetic, half_square)
    acceleration = system.to_lagrangian().acceleration(0.3, 0.6)
    np.testing.assert_allclose(acceleration, -0.3 * 0.64**1.5, rtol=1e-12)


def test_nystrom_splitting_refuses_a_relativistic_kinetic_energy():
    system = lj.SeparableHamiltonian(relativistic_kinetic, half_square)
    with pytest.raises(ValueError, match=r"Nyström.*not quadratic.*BlanesMoan6"):
        lj.simulate(system, (0.3, 0.6), t1=1.0, dt=0.1,
                    solver=lj.BlanesMoanNystrom6())  # fmt: skip


def test_nystrom_splitting_keeps_a_quadratic_kinetic_energy_undeclared():
    # T = p²/2 is read off its program: the oscillator's closed form cos t.
    system = lj.SeparableHamiltonian(half_square, half_square)
    trajectory = lj.simulate(system, (1.0, 0.0), t1=1.0, dt=0.05,
                             solver=lj.BlanesMoanNystrom6())  # fmt: skip
    np.testing.assert_allclose(trajectory.q[-1], np.cos(1.0), rtol=1e-9)


def relativistic_oscillator(q, qd):
    return -jnp.sqrt(1 - qd**2) - 0.5 * q**2


def test_declared_quadratic_in_velocity_is_verified():
    lagrangian = lj.Lagrangian(relativistic_oscillator, quadratic_in_velocity=True)
    with pytest.raises(ValueError, match=r"quadratic_in_velocity=True.*Drop"):
        lj.simulate(lagrangian, (1.0, 0.0), t1=3.0, dt=0.01)


def test_declared_quadratic_in_momentum_is_verified():
    hamiltonian = lj.Hamiltonian(
        lambda q, p: jnp.sqrt(1 + p**2) + 0.5 * q**2, quadratic_in_momentum=True
    )
    with pytest.raises(ValueError, match=r"quadratic_in_momentum=True.*Drop"):
        lj.simulate(hamiltonian, (1.0, 0.0), t1=1.0, dt=0.01)


def test_true_quadratic_declaration_is_accepted():
    # A mass matrix the program cannot prove quadratic (a solve), declared: runs.
    def kinetic(q, qd):
        mass = jnp.array([[2.0, 0.5], [0.5, 1.0]])
        return 0.5 * qd @ jnp.linalg.solve(jnp.linalg.inv(mass), qd) - 0.5 * q @ q

    lagrangian = lj.Lagrangian(kinetic, quadratic_in_velocity=True)
    y0 = (jnp.array([1.0, 0.0]), jnp.array([0.0, 0.3]))
    trajectory = lj.simulate(lagrangian, y0, t1=0.5, dt=0.05)
    assert trajectory.result == diffrax.RESULTS.successful


# -- Phase-space tools need an autonomous system ---------------------------------


def mathieu(q, qd, t):
    return 0.5 * qd**2 - 0.5 * (1.0 - 2 * 0.4 * jnp.cos(2 * t)) * q**2


def test_phase_space_tools_refuse_a_driven_system():
    system, y0 = lj.Lagrangian(mathieu), (0.1, 0.0)
    pattern = r"autonomous.*depend on t explicitly.*extended phase space"
    with pytest.raises(ValueError, match=pattern):
        lj.lyapunov_spectrum(system, y0, 10.0, dt=0.01)
    with pytest.raises(ValueError, match=pattern):
        lj.megno(system, y0, 10.0, dt=0.01)
    with pytest.raises(ValueError, match=pattern):
        lj.poincare_section(system, (jnp.array([0.1]), jnp.array([0.0])), 10.0,
                            lambda q, p: q, dt=0.01)  # fmt: skip


def test_phase_space_tools_refuse_a_drive_hidden_at_equilibrium():
    # At q = 0 the Mathieu rate is (0, 0) at every t: the probe beside y0 sees it.
    with pytest.raises(ValueError, match=r"autonomous"):
        lj.lyapunov_spectrum(lj.Lagrangian(mathieu), (0.0, 0.0), 10.0, dt=0.01)


def test_phase_space_tools_take_an_autonomous_l_that_accepts_t():
    # L(q, q̇, t, args) that ignores t: the oscillator's exponents are 0.
    def oscillator(q, qd, t, args):
        return 0.5 * qd**2 - 0.5 * args * q**2

    spectrum = lj.lyapunov_spectrum(
        lj.Lagrangian(oscillator), (0.1, 0.0), 20.0, dt=0.01, args=1.0
    )
    assert np.all(np.abs(np.asarray(spectrum.exponents)) < 0.2)


# -- Time and precision kept -----------------------------------------------------


def pendulum(q, qd):
    return 0.5 * qd**2 + jnp.cos(q)


def test_a_step_below_the_resolution_of_time_is_refused():
    # At t = 1e15 one ulp is 0.125: t0 + k·0.01 rounds to steps of 0 or 0.125.
    with pytest.raises(
        ValueError, match=r"too fine for times near 1e\+15.*starts at 0"
    ):
        lj.simulate(lj.Lagrangian(pendulum), (1.0, 0.0), t0=1e15, t1=1e15 + 1.0,
                    dt=0.01)  # fmt: skip


def test_a_float32_step_below_the_resolution_of_time_is_refused():
    y0 = (jnp.float32(1.0), jnp.float32(0.0))
    with pytest.raises(ValueError, match=r"float32.*starts at 0.*jax_enable_x64"):
        lj.simulate(lj.Lagrangian(pendulum), y0, t0=1e6, t1=1e6 + 1.0, dt=1e-3)


def test_float64_data_without_x64_warns():
    with (
        jax.enable_x64(False),
        pytest.warns(UserWarning, match=r"float32.*jax_enable_x64"),
    ):
        lj.simulate(lj.Lagrangian(pendulum), (np.float64(1.0), np.float64(0.0)),
                    t1=0.1, dt=0.01)  # fmt: skip
