"""Legendre transforms: round trips, Hamilton's equations, separable systems."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from tests.helpers import relative_close, tree_allclose

RNG = np.random.default_rng(1)


def double_pendulum(q, qd):
    t1, t2 = q[0], q[1]
    w1, w2 = qd[0], qd[1]
    return (
        w1**2
        + 0.5 * w2**2
        + w1 * w2 * jnp.cos(t1 - t2)
        + 9.81 * (2.0 * jnp.cos(t1) + jnp.cos(t2))
    )


def relativistic(q, qd, t, args):
    # Not quadratic in q̇: the Legendre transform needs Newton's method.
    mass, c, k = args
    return -mass * c**2 * jnp.sqrt(1.0 - qd @ qd / c**2) - 0.5 * k * q @ q


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize("quadratic", [True, False])
def test_round_trip_double_pendulum(quadratic):
    lag = lj.Lagrangian(double_pendulum, quadratic_in_velocity=quadratic)
    ham = lag.to_hamiltonian()
    # A plain Hamiltonian of the same function, so H → L takes the generic path.
    back = lj.Hamiltonian(lambda q, p: ham(q, p), quadratic_in_momentum=quadratic)
    back = back.to_lagrangian()
    for _ in range(4):
        q, qd = RNG.normal(size=2), RNG.normal(size=2)
        p = lag.momentum(q, qd)
        assert relative_close(back(q, qd), lag(q, qd), 1e-11)
        assert relative_close(back.momentum(q, qd), p, 1e-10)
        assert relative_close(ham(q, p), lag.energy(q, qd), 1e-11)
        assert relative_close(ham.velocity(q, p), qd, 1e-11)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_round_trip_relativistic_newton():
    args = (1.3, 2.0, 0.7)
    lag = lj.Lagrangian(relativistic)
    ham = lag.to_hamiltonian()
    back = lj.Hamiltonian(lambda q, p, t, a: ham(q, p, t, a)).to_lagrangian()
    mass, c, k = args
    for _ in range(3):
        q = RNG.normal(size=2)
        qd = RNG.uniform(-0.9, 0.9, size=2)  # |v| < c
        p = lag.momentum(q, qd, 0.0, args)
        # Closed form: H = c √(p² + m²c²) + ½ k q².
        expected = c * jnp.sqrt(p @ p + mass**2 * c**2) + 0.5 * k * q @ q
        assert relative_close(ham(q, p, 0.0, args), expected, 1e-12)
        assert relative_close(back(q, qd, 0.0, args), lag(q, qd, 0.0, args), 1e-10)


def test_hamilton_equations_match_euler_lagrange():
    # ṗ from H equals d/dt ∂L/∂q̇ = M q̈ + (∂p/∂q) q̇ along the Lagrangian flow.
    lag = lj.Lagrangian(double_pendulum, quadratic_in_velocity=True)
    ham = lag.to_hamiltonian()
    generic = lj.Hamiltonian(lambda q, p: ham(q, p), quadratic_in_momentum=True)
    q, qd = jnp.array([0.4, -1.0]), jnp.array([0.3, 0.8])
    p = lag.momentum(q, qd)
    qdd = lag.acceleration(q, qd)
    pdot = jax.jvp(lambda a, b: lag.momentum(a, b), (q, qd), (qd, qdd))[1]
    for h in (ham, generic):
        dq, dp = h.vector_field(q, p)
        assert relative_close(dq, qd, 1e-12)
        assert relative_close(dp, pdot, 1e-10)


def test_separable_hamiltonian_matches_general():
    T = lambda p: 0.5 * p @ p / 2.0
    V = lambda q, t, args: args * jnp.sum(q**4) - jnp.cos(t) * q[0]
    sep = lj.SeparableHamiltonian(T, V)
    general = lj.Hamiltonian(lambda q, p, t, args: T(p) + V(q, t, args))
    q, p = jnp.array([0.3, -0.2]), jnp.array([1.0, 0.4])
    assert np.isclose(sep(q, p, 0.5, 1.5), general(q, p, 0.5, 1.5))
    assert tree_allclose(
        sep.vector_field(q, p, 0.5, 1.5), general.vector_field(q, p, 0.5, 1.5)
    )
    lag = sep.to_lagrangian()
    assert np.isclose(
        lag(q, p / 2.0, 0.5, 1.5), 0.5 * 2.0 * (p / 2) @ (p / 2) - V(q, 0.5, 1.5)
    )


def test_dissipation_enters_legendre_vector_field():
    lag = lj.Lagrangian(
        lambda x, xd: 0.5 * 2.0 * xd**2 - 0.5 * 3.0 * x**2,
        dissipation=lambda xd: 0.5 * 0.4 * xd**2,
        quadratic_in_velocity=True,
    )
    dq, dp = lag.to_hamiltonian().vector_field(0.3, 2.0 * -1.1)
    assert np.isclose(dq, -1.1)
    assert np.isclose(dp, -3.0 * 0.3 - 0.4 * -1.1)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
def test_velocity_from_momentum_of_a_five_link_chain():
    # Five coordinates: the quadratic inverse in scalars with the unrolled LDLᵀ.
    # Closed form: p = M(q) q̇, M_ij = (n − max(i, j)) cos(θ_i − θ_j).
    from benchmarks.derivation_overhead import n_link_lagrangian, n_link_system

    hamiltonian = lj.Lagrangian(n_link_lagrangian).to_hamiltonian()
    q = jnp.linspace(0.3, 1.1, 5)
    qdot = jnp.array([0.4, -0.2, 0.7, 0.1, -0.5])
    mass, _ = n_link_system(q, qdot)
    p = mass @ qdot
    assert relative_close(hamiltonian.velocity(q, p), qdot, 1e-13)
    assert relative_close(jax.jit(hamiltonian.velocity)(q, p), qdot, 1e-13)
