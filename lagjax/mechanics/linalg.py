"""Small linear solves with a singularity check, for mass matrices and Hessians.

Mechanics solves M x = b where M = ∂²L/∂q̇∂q̇ (or ∂²H/∂p∂p) is small, symmetric and,
for physical systems, positive definite. Two forms:

- `solve_unrolled` works on Python lists of scalars for n ≤ 3 (closed-form inverse by
  cofactors). On CPU this keeps the whole integration step in one fused XLA kernel,
  which a batched `jnp.linalg.solve` on a 2×2 matrix does not (see
  `benchmarks/derivation_overhead.py`).
- `solve_dense` works on arrays of any size (LU with partial pivoting).

Both return a flag that is true when M is numerically singular; callers turn it into
a run-time error with `raise_if_singular` instead of passing on inf/NaN.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl

UNROLLED_SOLVE_LIMIT = 3

# A matrix counts as singular when its normalised determinant (for unrolled solves)
# or its smallest LU pivot relative to the largest (for dense solves) is below this
# many machine epsilons per dimension: at that conditioning a float64 solve has lost
# all its significant digits, so any result would be noise.
_SINGULAR_EPS_FACTOR = 64.0


def _singular_threshold(n: int, dtype) -> float:
    return _SINGULAR_EPS_FACTOR * n * float(jnp.finfo(dtype).eps)


def _cofactor_inverse(
    m: list[list[jax.Array]],
) -> tuple[list[list[jax.Array]], jax.Array]:
    """Adjugate and determinant of a symmetric 1×1, 2×2 or 3×3 matrix of scalars."""
    n = len(m)
    if n == 1:
        return [[jnp.ones_like(m[0][0])]], m[0][0]
    if n == 2:
        (a, b), (_, d) = m
        return [[d, -b], [-b, a]], a * d - b * b
    (a, b, c), (_, d, e), (_, _, f) = m
    adj = [
        [d * f - e * e, c * e - b * f, b * e - c * d],
        [c * e - b * f, a * f - c * c, b * c - a * e],
        [b * e - c * d, b * c - a * e, a * d - b * b],
    ]
    det = a * adj[0][0] + b * adj[0][1] + c * adj[0][2]
    return adj, det


def solve_unrolled(
    m: list[list[jax.Array]], rhs: list[jax.Array], *, poison: bool = False
) -> tuple[list[jax.Array], jax.Array]:
    """Solve a symmetric n ≤ 3 system given as lists of scalars.

    Only the upper triangle of `m` is read. Returns `(x, singular)`. With `poison`,
    a singular matrix makes x NaN: the determinant is replaced before the division,
    one scalar select that stays inside the fused kernel.
    """
    n = len(rhs)
    if n > UNROLLED_SOLVE_LIMIT:
        raise ValueError(
            f"unrolled solve supports n <= {UNROLLED_SOLVE_LIMIT}, got {n}"
        )
    adj, det = _cofactor_inverse(m)
    # For a positive definite M, |det| ≤ ∏ M_ii (Hadamard), so det / ∏ M_ii is a
    # scale-free measure in [0, 1]. (An indefinite M with a zero diagonal is never
    # flagged by it, correctly: its determinant is then not small.) Cheaper than a
    # Frobenius bound, which measured 1.8× the whole double-pendulum step.
    diagonal_product = m[0][0]
    for i in range(1, n):
        diagonal_product = diagonal_product * m[i][i]
    threshold = _singular_threshold(n, jnp.result_type(det))
    singular = jnp.abs(det) <= threshold * jnp.abs(diagonal_product)
    if poison:
        det = jnp.where(singular, jnp.nan, det)
    x = [sum(adj[i][j] * rhs[j] for j in range(n)) / det for i in range(n)]
    return x, singular


def solve_dense(m: jax.Array, rhs: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Solve m x = rhs by LU with partial pivoting. Returns `(x, singular)`."""
    n = m.shape[-1]
    lu, pivots = jsl.lu_factor(m)
    x = jsl.lu_solve((lu, pivots), rhs)
    pivot_sizes = jnp.abs(jnp.diagonal(lu))
    largest = jnp.max(pivot_sizes)
    singular = (largest == 0) | (
        jnp.min(pivot_sizes) <= _singular_threshold(n, m.dtype) * largest
    )
    return x, singular


def singular_message_for(what: str) -> str:
    """The error message for a singular matrix described by `what`."""
    return (
        f"{what} is singular at this state, so it cannot be inverted. Is the "
        "function degenerate (e.g. L linear in q̇), or is the state at a coordinate "
        "singularity (e.g. Euler-angle gimbal lock)?"
    )


def raise_if_singular(x, singular: jax.Array, what: str):
    """Attach a run-time error to `x` when `singular` is true (works inside jit)."""
    return eqx.error_if(x, singular, singular_message_for(what))
