r"""$LDL^T$ of a small symmetric matrix, unrolled into scalar arithmetic.

For the few coordinates of the scalar formulation (`euler_lagrange`,
`scalar_constraints`) a matrix is a Python list of JAX scalars. Factoring it
without pivoting, $M = LDL^T$ with unit lower-triangular L and diagonal D, takes
n³/6 multiply-adds written out as scalar operations, which XLA fuses into the
integration step around them, where a LAPACK call would split the step (its fixed
cost dominates at n ≤ 6). Without pivoting the factorization exists exactly when
every leading minor is nonzero, which a positive definite M guarantees; callers
judge the pivots (`pivots_sound`) and fall back to a pivoted dense solve when
they are not all clearly positive.

References: Golub & Van Loan, *Matrix Computations*, 4th ed., §4.1.2 ($LDL^T$).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

# A matrix counts as singular when its normalised determinant (unrolled cofactor
# solves), its smallest pivot relative to the largest (LDLᵀ, LU) is below this
# many machine epsilons per dimension: at that conditioning a float64 solve has lost
# all its significant digits, so any result would be noise.
SINGULAR_EPS_FACTOR = 64.0


class UnrolledLDL(NamedTuple):
    """The factors: `lower[i][k]` (k < i) of L, the pivots D as used (a pivot that
    is not positive replaced by 1) and as computed (`raw`, for the verdict)."""

    lower: list[list[jax.Array]]
    pivots: list[jax.Array]
    raw: list[jax.Array]


def _positive_or_one(pivot: Any) -> Any:
    return jnp.where(pivot > 0, pivot, jnp.ones_like(pivot))


def ldl_factor_unrolled(
    m: Sequence[Sequence[Any]], guard: Callable[[Any], Any] = _positive_or_one
) -> UnrolledLDL:
    """$LDL^T$ of a symmetric matrix given as lists of scalars (upper triangle read).

    By default (`guard`) a pivot that is not positive is replaced by 1 before it
    divides anything, so solves stay finite (and their derivatives NaN-free) where
    a caller will discard them on the verdict of `pivots_sound`. Scalars that are
    not JAX values (heyoka's expressions) take `guard=lambda pivot: pivot`.
    """
    n = len(m)
    lower: list[list[jax.Array]] = [[] for _ in range(n)]
    raw: list[jax.Array] = []
    pivots: list[jax.Array] = []
    for j in range(n):
        pivot = m[j][j]
        for k in range(j):
            pivot = pivot - lower[j][k] * lower[j][k] * pivots[k]
        raw.append(pivot)
        pivots.append(guard(pivot))
        for i in range(j + 1, n):
            entry = m[j][i]
            for k in range(j):
                entry = entry - lower[i][k] * lower[j][k] * pivots[k]
            lower[i].append(entry / pivots[j])
    return UnrolledLDL(lower, pivots, raw)


def ldl_solve_unrolled(factor: UnrolledLDL, rhs: list[jax.Array]) -> list[jax.Array]:
    """x with $LDL^T x$ = `rhs`: forward substitution, scaling, back substitution."""
    lower, pivots = factor.lower, factor.pivots
    n = len(rhs)
    y = []
    for i in range(n):
        value = rhs[i]
        for k in range(i):
            value = value - lower[i][k] * y[k]
        y.append(value)
    x: list[jax.Array] = [y[i] / pivots[i] for i in range(n)]
    for i in reversed(range(n)):
        for k in range(i + 1, n):
            x[i] = x[i] - lower[k][i] * x[k]
    return x


def pivots_sound(factor: UnrolledLDL) -> jax.Array:
    """Whether every pivot is positive and not tiny against the largest: then M is
    positive definite and far enough from singular for the solve to carry digits."""
    raw = factor.raw
    if not raw:  # an empty matrix (no constraints)
        return jnp.ones((), dtype=bool)
    smallest, largest = raw[0], raw[0]
    for pivot in raw[1:]:
        smallest, largest = jnp.minimum(smallest, pivot), jnp.maximum(largest, pivot)
    eps = float(jnp.finfo(jnp.result_type(smallest)).eps)
    return smallest > SINGULAR_EPS_FACTOR * len(raw) * eps * largest
