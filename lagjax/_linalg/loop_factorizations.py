r"""Cholesky and pivoted LU solves of small dense matrices as XLA loops.

**Why not LAPACK.** On CPU a LAPACK routine is a custom call, which XLA cannot
compile into the kernel around it: an integration step that solves by LAPACK —
even in a branch it rarely takes — is cut into separately dispatched pieces.
Written as `lax.fori_loop`s of plain array operations, the solves stay inside the
step's kernel. Measured in an RK4 scan of the n-link pendulum with the mass matrix
derived by autodiff (`benchmarks/derivation_overhead.py`, 2-core CPU) against the
hand-written twin that factors its closed-form M by LAPACK: n = 8 / 16, one
trajectory 0.64 / 0.77× with these loops against 1.38 / 1.50× with LAPACK, ×64
0.92 / 1.05× against 1.51 / 1.21×; with LAPACK only in the fallback branch (a
probe without the rest of lagjax's solve) 1.34 / 2.28×. Above 16 the loops run
faster still (n = 24: 0.55–0.64× one trajectory, 0.59× ×64, since the chain's
cumulative sums became short windows, `window_cumsum`) but compile for 4–7 s
against LAPACK's 1.1 s, at which LAPACK measures 1.00–1.12×: they would pay only
after about 10⁵ steps, so larger systems keep LAPACK (`LOOP_FACTORIZATION_LIMIT`).

**Cholesky** (Golub & Van Loan, *Matrix Computations*, 4th ed., Alg. 4.2.1, the
column or "gaxpy" form): column k of the lower factor L of $M = L L^T$ is

$$ s = M_{:,k} - L_{:,<k}\, L_{k,<k}^T, \qquad
   L_{:,k} = s / \sqrt{s_k} \quad (\text{rows } \ge k). $$

A matrix that is not positive definite gives a non-positive $s_k$, whose root is
NaN (or a division by zero): that column and every later one are NaN, so the
last diagonal entry of the factor tells whether the factorization held.

**LU with partial pivoting** (Golub & Van Loan, Alg. 3.4.1), applied to the right-
hand side as it goes: at step k the row with the largest $|a_{ik}|$, i ≥ k, is
swapped into place and eliminates the entries below the pivot. The pivots (the
diagonal of U) are returned for the caller's singularity verdict; an exactly zero
pivot eliminates nothing (so no NaN spreads into the other pivots) and its division
in the back substitution gives inf/NaN, never a finite wrong number.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

# Up to this many unknowns the solves are XLA loops; above, LAPACK.
LOOP_FACTORIZATION_LIMIT = 16


def _row(matrix: jax.Array, k) -> jax.Array:
    return jax.lax.dynamic_index_in_dim(matrix, k, axis=0, keepdims=False)


def _column(matrix: jax.Array, k) -> jax.Array:
    return jax.lax.dynamic_index_in_dim(matrix, k, axis=1, keepdims=False)


def cholesky_by_columns(m: jax.Array) -> jax.Array:
    """The lower Cholesky factor of the symmetric `m` (n × n; the lower triangle
    is read), column by column; NaN from the first column that fails onwards."""
    rows = jnp.arange(m.shape[-1])

    def factor_column(k, factor):
        s = _column(m, k) - factor @ _row(factor, k)
        column = jnp.where(rows >= k, s / jnp.sqrt(s[k]), 0.0)
        return jax.lax.dynamic_update_index_in_dim(factor, column, k, axis=1)

    return jax.lax.fori_loop(0, m.shape[-1], factor_column, jnp.zeros_like(m))


def _substitution(triangle: jax.Array, rhs: jax.Array, *, upper: bool) -> jax.Array:
    """x with T x = rhs for the lower (forward) or upper (backward) triangle T of
    `triangle`; the entries outside it meet only zeros of x."""
    n = rhs.shape[-1]

    def solve_row(i, x):
        # x holds zeros where it is not yet known, so a full row product reads
        # only the solved part.
        k = n - 1 - i if upper else i
        row = _row(triangle, k)
        return x.at[k].set((rhs[k] - row @ x) / row[k])

    return jax.lax.fori_loop(0, n, solve_row, jnp.zeros_like(rhs))


def solve_by_cholesky_factor(factor: jax.Array, rhs: jax.Array) -> jax.Array:
    """x with L Lᵀ x = rhs for the lower factor L (`cholesky_by_columns`)."""
    y = _substitution(factor, rhs, upper=False)
    return _substitution(factor.T, y, upper=True)


def solve_by_pivoted_lu(m: jax.Array, rhs: jax.Array) -> tuple[jax.Array, jax.Array]:
    """`(x, pivots)`: x with m x = rhs by LU with partial pivoting, and the
    diagonal of U."""
    n = m.shape[-1]
    rows = jnp.arange(n)

    def eliminate(k, carry):
        a, b = carry
        candidates = jnp.where(rows >= k, jnp.abs(_column(a, k)), -1.0)
        first_largest = jnp.min(jnp.where(candidates == jnp.max(candidates), rows, n))
        # The rows as masks and products with them, not indexing by the pivot:
        # under `vmap` the pivot differs per member, and gathers, scatters or a
        # reduction across rows would keep XLA from compiling the loop into the
        # step's kernel (n-link pendulum ×64: 1.5× against 0.95× the twin).
        is_pivot_row, is_row_k = rows == first_largest, rows == k
        pivot_row = is_pivot_row.astype(a.dtype)
        a_p, a_k, b_p, b_k = pivot_row @ a, _row(a, k), pivot_row @ b, b[k]
        a = jnp.where(is_row_k[:, None], a_p, jnp.where(is_pivot_row[:, None], a_k, a))
        b = jnp.where(is_row_k, b_p, jnp.where(is_pivot_row, b_k, b))
        pivot = a_p[k]
        factors = jnp.where(rows > k, _column(a, k), 0.0) / jnp.where(
            pivot == 0, 1.0, pivot
        )
        return a - factors[:, None] * a_p[None, :], b - factors * b_p

    upper, y = jax.lax.fori_loop(0, n, eliminate, (m, rhs))
    return _substitution(upper, y, upper=True), jnp.diagonal(upper)
