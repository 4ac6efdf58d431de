"""Euler–Lagrange accelerations of an n-link pendulum and of indefinite mass matrices.

The chain's L is written vector-style (`jnp.cumsum` of link velocities); its
accelerations must solve the closed-form equations of motion (unit masses and rods)

    M_ij = (n − max(i, j)) cos(θ_i − θ_j),
    M θ̈ = −Σ_j (n − max(i, j)) sin(θ_i − θ_j) θ̇_j² − g (n − i) sin θ_i,

on the scalar path (n = 3) and the dense one (n = 8, 16). A mass matrix need not be
positive definite: an indefinite one, even with a vanishing leading minor (where a
Cholesky or LDLᵀ without pivoting breaks down), is solved exactly; a singular one
raises on values and turns q̈ into NaN under a trace, never a finite wrong number.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from tests.helpers import relative_close

G = 9.81


def chain_lagrangian(q, qd):
    vx, vy = jnp.cumsum(jnp.cos(q) * qd), jnp.cumsum(jnp.sin(q) * qd)
    return 0.5 * jnp.sum(vx**2 + vy**2) + G * jnp.sum(jnp.cumsum(jnp.cos(q)))


def closed_form_acceleration(q, qd):
    n = q.shape[0]
    index = np.arange(n)
    weight = n - np.maximum(index[:, None], index[None, :])
    difference = q[:, None] - q[None, :]
    rhs = -(weight * np.sin(difference)) @ qd**2 - G * (n - index) * np.sin(q)
    return np.linalg.solve(weight * np.cos(difference), rhs)


@pytest.mark.parametrize("n", [3, 8, 16])
def test_chain_matches_closed_form_mass_matrix_solve(n):
    rng = np.random.default_rng(n)
    q, qd = rng.uniform(-1.0, 1.0, size=n), rng.normal(size=n)
    derived = lj.Lagrangian(chain_lagrangian).acceleration(jnp.asarray(q), qd)
    assert relative_close(derived, closed_form_acceleration(q, qd), 1e-10)


def indefinite_mass(n):
    """Symmetric, nonsingular, indefinite, with M_00 = 0 (first leading minor 0)."""
    rng = np.random.default_rng(n)
    a = rng.normal(size=(n, n))
    mass = a + a.T
    mass[0, 0] = 0.0
    return mass


def quadratic_lagrangian(mass):
    return lambda q, qd: 0.5 * qd @ mass @ qd - 0.5 * q @ q


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize("n", [2, 5, 8])
def test_indefinite_mass_matrix_with_zero_leading_minor_is_solved(n):
    mass = indefinite_mass(n)
    eigenvalues = np.linalg.eigvalsh(mass)
    assert eigenvalues.min() < 0 < eigenvalues.max()
    q = np.linspace(-1.0, 1.0, n)
    lag = lj.Lagrangian(quadratic_lagrangian(jnp.asarray(mass)))
    expected = np.linalg.solve(mass, -q)  # M q̈ = ∂L/∂q = −q
    assert relative_close(
        lag.acceleration(jnp.asarray(q), jnp.ones(n)), expected, 1e-12
    )
    traced = jax.jit(lag.acceleration)(jnp.asarray(q), jnp.ones(n))
    assert relative_close(traced, expected, 1e-12)


@pytest.mark.integration  # compile-heavy: CI runs it in its integration step
@pytest.mark.parametrize("n", [2, 5, 8])
def test_singular_mass_matrix_raises_or_is_nan_under_a_trace(n):
    mass = indefinite_mass(n)
    mass[:, -1] = mass[:, 0]
    mass[-1, :] = mass[0, :]  # two equal rows and columns: singular, symmetric
    lag = lj.Lagrangian(quadratic_lagrangian(jnp.asarray(mass)))
    q, qd = jnp.linspace(-1.0, 1.0, n), jnp.ones(n)
    with pytest.raises(Exception, match="singular"):
        lag.acceleration(q, qd)
    assert bool(jnp.all(jnp.isnan(jax.jit(lag.acceleration)(q, qd))))
