r"""LU with partial pivoting of a small general matrix, unrolled into scalars.

Newton's method inside an integration step (the variational midpoint step, the
projection onto constraints) solves J δ = r with a small, generally unsymmetric
Jacobian at every iteration. Written out as scalar operations — the row swaps as
selects on comparisons, not as indexing by the pivot — the elimination takes
n³/3 multiply-adds that XLA compiles into the step's kernel, as a hand-written
Cramer's rule would be; a LAPACK call there is a custom call, which cuts the loop
body into separately dispatched pieces (`loop_factorizations`).

Partial pivoting (Golub & Van Loan, *Matrix Computations*, 4th ed., Alg. 3.4.1):
at step k the row i ≥ k with the largest $|a_{ik}|$ (the first such row on a tie)
becomes the pivot row and eliminates the entries below it. An exactly zero pivot
eliminates nothing, so no NaN spreads into the other pivots; its division in the
back substitution gives inf/NaN, never a finite wrong number. The pivots (the
diagonal of U) are returned for the caller's singularity verdict.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp

# Up to this many unknowns the unrolled elimination (n³/3 scalar operations in
# the program) is used; above, the XLA loops of `loop_factorizations`.
UNROLLED_LU_LIMIT = 6

_Rows = list[list[jax.Array]]


def _swap_in_pivot_row(rows: _Rows, k: int) -> _Rows:
    """`rows` with row k exchanged for the row i ≥ k of the largest |entry k|."""
    pivot_row, pivot_size = rows[k], jnp.abs(rows[k][k])
    chosen = [jnp.zeros((), dtype=bool) for _ in rows]
    for i in range(k + 1, len(rows)):
        larger = jnp.abs(rows[i][k]) > pivot_size
        pivot_size = jnp.where(larger, jnp.abs(rows[i][k]), pivot_size)
        pivot_row = [jnp.where(larger, a, b) for a, b in zip(rows[i], pivot_row)]
        chosen = [(c & ~larger) for c in chosen]
        chosen[i] = larger
    swapped = list(rows)
    swapped[k] = pivot_row
    for i in range(k + 1, len(rows)):
        swapped[i] = [jnp.where(chosen[i], a, b) for a, b in zip(rows[k], rows[i])]
    return swapped


def lu_solve_unrolled(
    m: Sequence[Sequence[Any]], rhs: Sequence[Any]
) -> tuple[list[jax.Array], list[jax.Array]]:
    """`(x, pivots)`: x with m x = rhs (lists of scalars) by LU with partial
    pivoting, and the diagonal of U."""
    n = len(rhs)
    # Each row carries its right-hand side as a last column, so one swap moves both.
    rows: _Rows = [
        [jnp.asarray(a) for a in m[i]] + [jnp.asarray(rhs[i])] for i in range(n)
    ]
    for k in range(n):
        rows = _swap_in_pivot_row(rows, k)
        pivot = rows[k][k]
        safe_pivot = jnp.where(pivot == 0, jnp.ones_like(pivot), pivot)
        for i in range(k + 1, n):
            factor = rows[i][k] / safe_pivot
            rows[i] = rows[i][:k] + [
                a - factor * b for a, b in zip(rows[i][k:], rows[k][k:])
            ]
    x: list[jax.Array] = [jnp.zeros(())] * n
    for i in reversed(range(n)):
        value = rows[i][n]
        for j in range(i + 1, n):
            value = value - rows[i][j] * x[j]
        x[i] = value / rows[i][i]
    return x, [rows[k][k] for k in range(n)]
