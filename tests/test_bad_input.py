"""Bad input gets an error that names the problem, never a silent wrong number."""

import jax
import jax.numpy as jnp
import pytest

import lagjax as lj
from tests.helpers import assert_singular_verdicts


def test_lagrangian_returning_a_vector_is_rejected():
    lag = lj.Lagrangian(lambda q, qd: 0.5 * qd**2 - 0.5 * q**2)
    with pytest.raises(ValueError, match="must return a scalar"):
        lag.acceleration(jnp.ones(2), jnp.ones(2))


def test_hamiltonian_returning_a_vector_is_rejected():
    ham = lj.Hamiltonian(lambda q, p: p**2)
    with pytest.raises(ValueError, match="must return a scalar"):
        ham.vector_field(jnp.ones(3), jnp.ones(3))


def test_mismatched_q_and_qdot_shapes():
    lag = lj.Lagrangian(lambda q, qd: jnp.sum(qd**2) - jnp.sum(q**2))
    with pytest.raises(ValueError, match="same shapes"):
        lag.acceleration(jnp.ones(2), jnp.ones(3))


def test_mismatched_q_and_qdot_structures():
    lag = lj.Lagrangian(lambda q, qd: jnp.sum(qd[0] ** 2))
    with pytest.raises(ValueError, match="same pytree structure"):
        lag.acceleration((jnp.ones(2), jnp.ones(2)), jnp.ones(2))


def test_mismatched_q_and_p():
    ham = lj.Hamiltonian(lambda q, p: jnp.sum(p**2) + jnp.sum(q**2))
    with pytest.raises(ValueError, match="same shapes"):
        ham.vector_field(jnp.ones(2), jnp.ones(1))


def test_function_with_too_few_arguments():
    with pytest.raises(TypeError, match="at least 2 positional arguments"):
        lj.Lagrangian(lambda q: q**2)


def test_degenerate_lagrangian_raises_eagerly_and_poisons_under_jit():
    # L linear in q̇: the mass matrix vanishes and q̈ is undetermined. Called on
    # values: a clear error. Traced (inside jit or a loop): NaN, which costs no
    # branch in the fused step; check=True raises there too.
    lag = lj.Lagrangian(lambda q, qd: jnp.sum(q * qd) - jnp.sum(q**2))
    assert_singular_verdicts(lag, jnp.ones(2), jnp.ones(2), "singular")


def test_degenerate_lagrangian_dense_path_raises():
    lag = lj.Lagrangian(lambda q, qd: jnp.sum(q[1:] * qd[1:]) + 0.5 * qd[0] ** 2)
    with pytest.raises(Exception, match="singular"):
        jax.block_until_ready(lag.acceleration(jnp.ones(9), jnp.ones(9)))
    checked = jax.jit(lambda q, qd: lag.acceleration(q, qd, check=True))
    with pytest.raises(Exception, match="singular"):
        jax.block_until_ready(checked(jnp.ones(9), jnp.ones(9)))


def test_unchecked_acceleration_is_not_finite():
    lag = lj.Lagrangian(lambda q, qd: jnp.sum(q * qd) - jnp.sum(q**2))
    acc = jax.jit(lambda q, qd: lag.acceleration(q, qd, check=False))(
        jnp.ones(2), jnp.ones(2)
    )
    assert not bool(jnp.any(jnp.isfinite(acc)))


def test_degenerate_legendre_transform_raises():
    # On values: an error. Under a trace: NaN (no branch in the step), or an error
    # with check=True.
    lag = lj.Lagrangian(lambda q, qd: q * qd - q**2, quadratic_in_velocity=True)
    ham = lag.to_hamiltonian()
    with pytest.raises(Exception, match="singular"):
        jax.block_until_ready(ham.velocity(1.0, 2.0))
    assert bool(jnp.isnan(jax.jit(ham)(1.0, 2.0)))
    checked = jax.jit(lambda q, p: ham.vector_field(q, p, check=True))
    with pytest.raises(Exception, match="singular"):
        jax.block_until_ready(checked(1.0, 2.0))


def test_singular_hamiltonian_hessian_raises():
    ham = lj.Hamiltonian(lambda q, p: q * p)
    lag = ham.to_lagrangian()
    with pytest.raises(Exception, match="singular"):
        jax.block_until_ready(jax.jit(lag)(1.0, 2.0))


def test_normal_modes_need_positive_kinetic_matrix():
    lag = lj.Lagrangian(lambda q, qd: -0.5 * jnp.sum(qd**2) - 0.5 * jnp.sum(q**2))
    with pytest.raises(Exception, match="not positive definite"):
        jax.block_until_ready(lj.normal_modes(lag, jnp.zeros(2)))
