"""Cumulative reductions (jnp.cumsum & co.) in the scalar twin of a Lagrangian.

A chain written vector-style sums link velocities with `jnp.cumsum`; the twin must
give the same value as the array function, and the accelerations derived from it
must solve the closed-form equations of motion of the n-link pendulum.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax._linalg.scalarize import as_object_array, scalarize
from tests.helpers import relative_close

G = 9.81


def cumulative_mix(x):
    grid = x.reshape(2, 3)
    return (
        jnp.sum(jnp.cumsum(x) ** 2)
        + jnp.sum(jax.lax.cumsum(x[::-1], reverse=True) * jnp.cumprod(x))
        + jnp.sum(jax.lax.cummax(x, reverse=True))
        + jnp.sum(jnp.cumsum(grid, axis=0) * jax.lax.cummin(grid, axis=1))
    )


def test_cumulative_reductions_scalarize_to_the_same_value():
    x = jnp.array([0.3, -1.2, 2.0, 0.5, -0.7, 1.1])
    twin = scalarize(cumulative_mix, x)
    assert twin is not None
    assert relative_close(twin(as_object_array(x)), cumulative_mix(x), 1e-14)


def chain_lagrangian(q, qd):
    """n unit masses on unit rods, the positions as cumulative sums."""
    vx, vy = jnp.cumsum(jnp.cos(q) * qd), jnp.cumsum(jnp.sin(q) * qd)
    return 0.5 * jnp.sum(vx**2 + vy**2) + G * jnp.sum(jnp.cumsum(jnp.cos(q)))


@pytest.mark.parametrize("n", [2, 4])
def test_chain_acceleration_solves_closed_form_equations(n):
    # M_ij = (n − max(i, j)) cos(θ_i − θ_j),
    # M θ̈ = −Σ_j (n − max(i, j)) sin(θ_i − θ_j) θ̇_j² − g (n − i) sin θ_i.
    rng = np.random.default_rng(n)
    q, qd = rng.normal(size=n), rng.normal(size=n)
    index = np.arange(n)
    weight = n - np.maximum(index[:, None], index[None, :])
    difference = q[:, None] - q[None, :]
    rhs = -(weight * np.sin(difference)) @ qd**2 - G * (n - index) * np.sin(q)
    expected = np.linalg.solve(weight * np.cos(difference), rhs)
    # The chain is derived through its scalar twin (the cumsums are scalarized).
    assert scalarize(chain_lagrangian, jnp.asarray(q), jnp.asarray(qd)) is not None
    derived = lj.Lagrangian(chain_lagrangian).acceleration(jnp.asarray(q), qd)
    assert relative_close(derived, expected, 1e-11)
