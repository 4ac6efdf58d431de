"""`loop_factorizations`: Cholesky and pivoted LU as XLA loops, against NumPy/LAPACK.

The solves are checked against NumPy's on positive definite, indefinite (zero
leading minor: pivoting needed) and singular matrices; the LU pivots against
LAPACK's; a failed Cholesky must mark its last diagonal entry, and an exactly
singular LU solve must not return a finite number. Under `vmap` the members are
solved independently (each its own pivot rows).
"""

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
import pytest

from lagjax._linalg.loop_factorizations import (
    cholesky_by_columns,
    solve_by_cholesky_factor,
    solve_by_pivoted_lu,
)
from lagjax._linalg.small_solves import solve_dense, solve_dense_in_step
from tests.helpers import relative_close
from tests.test_spd_solve import (
    _factorization_shapes,
    indefinite_zero_minor,
    positive_definite,
    singular_symmetric,
)


@pytest.mark.parametrize("n", [1, 2, 7, 16])
def test_cholesky_factor_and_solve_match_numpy(n):
    rng = np.random.default_rng(n)
    mass, rhs = positive_definite(rng, n), rng.normal(size=n)
    factor = jax.jit(cholesky_by_columns)(jnp.asarray(mass))
    assert relative_close(factor, np.linalg.cholesky(mass), 1e-13)
    assert np.all(np.triu(np.asarray(factor), 1) == 0)
    x = jax.jit(solve_by_cholesky_factor)(factor, jnp.asarray(rhs))
    assert relative_close(x, np.linalg.solve(mass, rhs), 1e-12)


def test_failed_cholesky_marks_the_last_diagonal_entry():
    rng = np.random.default_rng(5)
    for mass in (indefinite_zero_minor(rng), singular_symmetric(rng), -np.eye(7)):
        factor = cholesky_by_columns(jnp.asarray(mass))
        assert not np.isfinite(factor[-1, -1])
    late = positive_definite(rng)
    late[-1, -1] = -100.0  # fails only at the last column
    assert not np.isfinite(cholesky_by_columns(jnp.asarray(late))[-1, -1])


@pytest.mark.parametrize("make", [positive_definite, indefinite_zero_minor])
@pytest.mark.parametrize("n", [2, 7, 16])
def test_pivoted_lu_solves_and_pivots_as_lapack(make, n):
    rng = np.random.default_rng(10 + n)
    mass, rhs = make(rng, n), rng.normal(size=n)
    x, pivots = jax.jit(solve_by_pivoted_lu)(jnp.asarray(mass), jnp.asarray(rhs))
    assert relative_close(x, np.linalg.solve(mass, rhs), 1e-11)
    lu, _ = jsl.lu_factor(jnp.asarray(mass))
    assert relative_close(jnp.abs(pivots), jnp.abs(jnp.diagonal(lu)), 1e-12)


def test_pivoted_lu_of_a_singular_matrix_is_never_a_finite_answer():
    rng = np.random.default_rng(6)
    rhs = jnp.asarray(rng.normal(size=7))
    for mass in (np.zeros((7, 7)), np.outer(np.arange(1.0, 8.0), np.ones(7))):
        x, pivots = solve_by_pivoted_lu(jnp.asarray(mass), rhs)
        assert not np.all(np.isfinite(x))
        assert np.min(np.abs(pivots)) == 0.0


def test_pivoted_lu_under_vmap_pivots_each_member_on_its_own():
    rng = np.random.default_rng(7)
    masses = np.stack(
        [indefinite_zero_minor(rng), positive_definite(rng), indefinite_zero_minor(rng)]
    )
    # Different pivot rows per member: a permuted copy of the first.
    masses[2] = masses[0][::-1]
    rhs = rng.normal(size=(3, 7))
    x, _ = jax.jit(jax.vmap(solve_by_pivoted_lu))(jnp.asarray(masses), rhs)
    expected = np.linalg.solve(masses, rhs[..., None])[..., 0]
    assert relative_close(x, expected, 1e-11)


def test_solve_dense_in_step_calls_no_lapack_on_cpu():
    # The constrained systems' saddle solve: loops on CPU (inside the step's
    # kernel), one LAPACK LU elsewhere; same answer and verdict as `solve_dense`.
    rng = np.random.default_rng(8)
    mass, rhs = jnp.asarray(indefinite_zero_minor(rng)), jnp.asarray(rng.normal(size=7))
    assert _factorization_shapes(solve_dense_in_step, "cpu", mass, rhs) == {}
    on_gpu = _factorization_shapes(solve_dense_in_step, "cuda", mass, rhs)
    assert on_gpu == {"getrf": {"7x7"}}
    x, singular = jax.jit(solve_dense_in_step)(mass, rhs)
    assert relative_close(x, np.linalg.solve(np.asarray(mass), rhs), 1e-11)
    assert not bool(singular)
    zero = jnp.zeros((7, 7))
    assert bool(solve_dense_in_step(zero, rhs)[1]) and bool(solve_dense(zero, rhs)[1])
