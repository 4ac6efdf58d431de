"""Correctness of the fast paths: the quadratic-degree reading of a Lagrangian, the
scalar Legendre inverse it enables, and the derived right-hand sides at every size.

Physics is the oracle: closed-form mass matrices, never the code's earlier output.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lagjax as lj
from lagjax.mechanics.legendre import invert_gradient, is_at_most_quadratic

G = 9.81


def double_pendulum(q, qd):
    w1, w2 = qd[0], qd[1]
    kinetic = w1**2 + 0.5 * w2**2 + w1 * w2 * jnp.cos(q[0] - q[1])
    return kinetic + G * (2.0 * jnp.cos(q[0]) + jnp.cos(q[1]))


def double_pendulum_mass(q):
    c = jnp.cos(q[0] - q[1])
    return jnp.array([[2.0, c], [c, 1.0]])


V = jnp.array([0.3, -0.7])


@pytest.mark.parametrize(
    ("function", "expected"),
    [
        (lambda v: double_pendulum(jnp.array([0.4, 1.1]), v), True),
        (lambda v: jnp.sum(jnp.cumsum(v) ** 2) + jnp.sin(1.0) * v[0], True),
        (lambda v: 0.5 * v @ double_pendulum_mass(jnp.ones(2)) @ v, True),
        (lambda v: v[0] * v[1] + 3.0 * v[1] - jnp.exp(2.0), True),
        (lambda v: v[0] ** 2 * v[1], False),  # cubic
        (lambda v: -jnp.sqrt(1.0 - v @ v), False),  # relativistic
        (lambda v: jnp.cos(v[0]), False),
        (lambda v: jnp.where(v[0] > 0, v[0] ** 2, 0.0), False),  # branch on v
        (lambda v: jnp.abs(v[0]) * v[1], False),
        (lambda v: v[0] ** 2 / v[1], False),
        (lambda v: v[0] * v[1].astype(int), False),  # truncation
    ],
)
def test_quadratic_degree_is_read_from_the_program(function, expected):
    assert is_at_most_quadratic(function, V) is expected


@pytest.mark.parametrize("n", [2, 5, 8])
def test_undeclared_quadratic_legendre_inverse_is_the_linear_solve(n):
    # L = ½ q̇ᵀ M q̇ + a·q̇ with a fixed SPD M: q̇ = M⁻¹ (p − a) in closed form. Not
    # declared quadratic, so the degree reading picks the linear solve (scalar
    # arithmetic for n ≤ 6, dense beyond).
    rng = np.random.default_rng(n)
    root = rng.normal(size=(n, n))
    mass = jnp.asarray(root @ root.T + n * np.eye(n))
    drift = jnp.asarray(rng.normal(size=n))
    p = jnp.asarray(rng.normal(size=n))
    lag = lj.Lagrangian(lambda q, qd: 0.5 * qd @ mass @ qd + drift @ qd - q @ q)
    qdot = lag.to_hamiltonian().velocity(jnp.zeros(n), p)
    np.testing.assert_allclose(qdot, jnp.linalg.solve(mass, p - drift), rtol=1e-13)


def test_double_pendulum_velocity_matches_closed_form_mass_matrix():
    q, p = jnp.array([1.2, -0.4]), jnp.array([0.5, -2.0])
    qdot = lj.Lagrangian(double_pendulum).to_hamiltonian().velocity(q, p)
    expected = jnp.linalg.solve(double_pendulum_mass(q), p)
    np.testing.assert_allclose(qdot, expected, rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("n", [1, 2, 4])
def test_singular_quadratic_inverse_raises_or_poisons(n):
    def linear_in_v(v):  # Hessian zero: no inverse
        return jnp.sum(v) + 0.0 * jnp.sum(v**2)

    with pytest.raises(Exception, match="singular"):
        jax.block_until_ready(
            jax.jit(
                lambda p: invert_gradient(linear_in_v, p, quadratic=False, what="H")
            )(jnp.ones(n))
        )
    poisoned = jax.jit(
        lambda p: invert_gradient(
            linear_in_v, p, quadratic=False, what="H", check="nan"
        )
    )(jnp.ones(n))
    assert bool(jnp.all(jnp.isnan(poisoned)))


def n_link_lagrangian(q, qd):
    """n unit masses on unit rods, written vector-style with cumulative sums."""
    vx, vy = jnp.cumsum(jnp.cos(q) * qd), jnp.cumsum(jnp.sin(q) * qd)
    return 0.5 * jnp.sum(vx**2 + vy**2) + G * jnp.sum(jnp.cumsum(jnp.cos(q)))


def n_link_acceleration(q, qd):
    """Closed form: M_ij = (n − max(i, j)) cos(θ_i − θ_j) (0-based), and
    M q̈ = −Σ_j (n − max(i, j)) sin(θ_i − θ_j) θ̇_j² − g (n − i) sin θ_i."""
    n = q.shape[0]
    index = np.arange(n)
    weight = n - np.maximum(index[:, None], index[None, :])
    difference = q[:, None] - q[None, :]
    rhs = -(weight * jnp.sin(difference)) @ qd**2 - G * (n - index) * jnp.sin(q)
    return jnp.linalg.solve(weight * jnp.cos(difference), rhs)


@pytest.mark.parametrize("n", [4, 9])
def test_n_link_pendulum_acceleration_matches_closed_form(n):
    # n = 4: scalar formulation; n = 9: dense formulation.
    q, qd = jnp.linspace(0.3, -1.1, n), jnp.linspace(-0.5, 0.8, n)
    qddot = lj.Lagrangian(n_link_lagrangian).acceleration(q, qd)
    np.testing.assert_allclose(
        qddot, n_link_acceleration(q, qd), rtol=1e-11, atol=1e-11
    )
