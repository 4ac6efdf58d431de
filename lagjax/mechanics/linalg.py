"""Small linear solves with a singularity check, for mass matrices and Hessians.

Mechanics solves M x = b where M = ∂²L/∂q̇∂q̇ (or ∂²H/∂p∂p) is small, symmetric and,
for physical systems, positive definite. Four forms:

- `solve_unrolled` works on Python lists of scalars for n ≤ 3 (closed-form inverse by
  cofactors). On CPU this keeps the whole integration step in one fused XLA kernel,
  which a batched `jnp.linalg.solve` on a 2×2 matrix does not (see
  `benchmarks/derivation_overhead.py`).
- `solve_unrolled_symmetric` works on lists of scalars for a few more (the scalar
  formulation's 4–6 coordinates): unrolled LDLᵀ, fused like the cofactor form,
  with the LU fallback of `solve_symmetric` for an indefinite or singular M.
- `solve_dense` works on arrays of any size (LU with partial pivoting).
- `solve_symmetric` works on arrays of any size for a symmetric M that is usually
  positive definite: Cholesky (half the work of LU, and what a hand-written solver
  of a physical M uses), with LU as the fallback for the rare indefinite or
  ill-conditioned M — decided per batch under `vmap` (see its docstring).

All return a flag that is true when M is numerically singular; callers turn it into
a run-time error with `raise_if_singular` instead of passing on inf/NaN.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np

from ..batch_branch import any_in_batch

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


def _lu_verdict(m: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """LU factors of m and its singular flag (smallest pivot against the largest)."""
    n = m.shape[-1]
    lu, pivots = jsl.lu_factor(m)
    pivot_sizes = jnp.abs(jnp.diagonal(lu))
    largest = jnp.max(pivot_sizes)
    singular = (largest == 0) | (
        jnp.min(pivot_sizes) <= _singular_threshold(n, m.dtype) * largest
    )
    return lu, pivots, singular


def solve_dense(m: jax.Array, rhs: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Solve m x = rhs by LU with partial pivoting. Returns `(x, singular)`."""
    lu, pivots, singular = _lu_verdict(m)
    return jsl.lu_solve((lu, pivots), rhs), singular


class _SymmetricFactors(NamedTuple):
    fallback: jax.Array  # LU was formed (for some member, under vmap)
    sound: jax.Array  # this member's Cholesky factor is used
    cholesky: jax.Array  # the identity where not sound, so never NaN
    lu: jax.Array  # zeros when LU was not formed
    pivots: jax.Array
    singular: jax.Array


def _sound_cholesky(m: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The Cholesky factor of m and whether it is sound (exists, well conditioned)."""
    # Reads the lower triangle only; a failed factorization comes back as NaN.
    cholesky = jax.lax.linalg.cholesky(m, symmetrize_input=False)
    squared_pivots = jnp.diagonal(cholesky) ** 2  # the pivots of LDLᵀ
    # False for NaN, zero or relatively tiny pivots: then LU solves and judges.
    threshold = _singular_threshold(m.shape[-1], m.dtype)
    return cholesky, jnp.min(squared_pivots) > threshold * jnp.max(squared_pivots)


def _factor_symmetric(m: jax.Array) -> _SymmetricFactors:
    """Cholesky factor, whether it is sound, and LU factors only when needed."""
    n = m.shape[-1]
    cholesky, sound = _sound_cholesky(m)

    def with_lu():
        lu, pivots, singular = _lu_verdict(m)
        # A member whose Cholesky failed must not carry NaN into the (discarded)
        # Cholesky solve: 0 × NaN would reach the gradient.
        safe = jnp.where(sound, cholesky, jnp.eye(n, dtype=m.dtype))
        return safe, lu, pivots, ~sound & singular

    def without_lu():
        pivots = jnp.zeros(m.shape[:-1], dtype=np.int32)
        return cholesky, jnp.zeros_like(m), pivots, jnp.zeros((), dtype=bool)

    fallback = any_in_batch(~sound)
    return _SymmetricFactors(
        fallback, sound, *jax.lax.cond(fallback, with_lu, without_lu)
    )


def _solve_factored(factors: _SymmetricFactors, rhs: jax.Array) -> jax.Array:
    by_cholesky = jsl.cho_solve((factors.cholesky, True), rhs)

    def with_lu():
        by_lu = jsl.lu_solve((factors.lu, factors.pivots), rhs)
        return jnp.where(factors.sound, by_cholesky, by_lu)

    return jax.lax.cond(factors.fallback, with_lu, lambda: by_cholesky)


@jax.custom_jvp
def solve_symmetric(m: jax.Array, rhs: jax.Array) -> tuple[jax.Array, jax.Array]:
    r"""Solve m x = rhs for a symmetric m, by Cholesky when m is positive definite.

    Only the lower triangle of m is read by Cholesky. Returns `(x, singular)`.
    When the Cholesky factor exists and no squared diagonal entry of it (the
    pivots of $LDL^T$) is below `solve_dense`'s relative threshold, m counts as
    nonsingular and LU is never formed; otherwise (m indefinite, singular or
    nearly so) LU with partial pivoting solves and judges, as `solve_dense` does.
    An indefinite but nonsingular m is therefore solved exactly too.

    The fallback is a `lax.cond`. Under `vmap` a batched predicate would turn it
    into a select that runs both factorizations for every member; here the
    predicate is reduced over the batch first (`jax.custom_batching.custom_vmap`),
    so LU runs only when some member needs it, and then only those members take
    its answer.

    Derivatives reuse the factors: $dx = m^{-1}(d\,\mathrm{rhs} - dm\,x)$ (a
    custom JVP, linear in the tangents, so reverse mode transposes it; JAX's own
    Cholesky JVP would cost two triangular solves with a matrix, and propagate
    the NaN of a failed factorization).
    """
    # Factorization and solve in one branch each: one `cond` per call, where the
    # derivative rule, which solves twice with the same factors, needs two.
    cholesky, sound = _sound_cholesky(m)

    def with_lu():
        by_lu, singular = solve_dense(m, rhs)
        by_cholesky = jsl.cho_solve((cholesky, True), rhs)
        return jnp.where(sound, by_cholesky, by_lu), ~sound & singular

    def without_lu():
        return jsl.cho_solve((cholesky, True), rhs), jnp.zeros((), dtype=bool)

    return jax.lax.cond(any_in_batch(~sound), with_lu, without_lu)


@solve_symmetric.defjvp
def _solve_symmetric_jvp(primals, tangents) -> tuple[Any, Any]:
    m, rhs = primals
    dm, drhs = tangents
    factors = _factor_symmetric(m)
    x = _solve_factored(factors, rhs)
    dx = _solve_factored(factors, drhs - dm @ x)
    no_tangent = np.zeros(factors.singular.shape, dtype=jax.dtypes.float0)
    return (x, factors.singular), (dx, no_tangent)


def _unrolled_ldl_solve(
    m: list[list[jax.Array]], rhs: list[jax.Array]
) -> tuple[list[jax.Array], list[jax.Array]]:
    """x from M = L D Lᵀ without pivoting, in scalars, and the pivots D (raw).

    Only the upper triangle of `m` is read. A pivot that is not positive is
    replaced by 1 before it divides anything, so the answer stays finite (and its
    derivatives NaN-free) where it will be discarded.
    """
    n = len(rhs)
    lower: list[list[jax.Array]] = [[] for _ in range(n)]  # lower[i][k], k < i
    raw, pivots = [], []
    for j in range(n):
        pivot = m[j][j]
        for k in range(j):
            pivot = pivot - lower[j][k] * lower[j][k] * pivots[k]
        raw.append(pivot)
        pivots.append(jnp.where(pivot > 0, pivot, jnp.ones_like(pivot)))
        for i in range(j + 1, n):
            entry = m[j][i]
            for k in range(j):
                entry = entry - lower[i][k] * lower[j][k] * pivots[k]
            lower[i].append(entry / pivots[j])
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
    return x, raw


def solve_unrolled_symmetric(
    m: list[list[jax.Array]],
    rhs: list[jax.Array],
    system: Callable[[], tuple[list[list[jax.Array]], list[jax.Array]]] | None = None,
) -> tuple[jax.Array, jax.Array]:
    """Solve a symmetric system given as lists of scalars (upper triangle read).

    $LDL^T$ without pivoting, unrolled into scalar arithmetic, which fuses into
    the surrounding step (no LAPACK call, whose fixed cost dominates at n ≤ 6);
    when a pivot is not positive or below `solve_dense`'s relative threshold (M
    indefinite, singular or nearly so), LU with partial pivoting on the assembled
    matrix solves and judges, in a `lax.cond` whose predicate is reduced over the
    batch under `vmap`, as in `solve_symmetric`. Returns `(x, singular)`.

    `system`, when given, returns `(m, rhs)` again: the fallback branch calls it
    instead of taking the n² + n scalars as its operands, so that its operands are
    the (few) inputs they were computed from. Handing the branch the scalars made
    XLA split the fused step around them: the n-link pendulum's step at n = 6 went
    from 0.27× to 1.9× its hand-written twin (`benchmarks/derivation_overhead.py`).
    """
    n = len(rhs)
    x, raw = _unrolled_ldl_solve(m, rhs)
    smallest, largest = raw[0], raw[0]
    for pivot in raw[1:]:
        smallest, largest = jnp.minimum(smallest, pivot), jnp.maximum(largest, pivot)
    sound = smallest > _singular_threshold(n, jnp.result_type(smallest)) * largest
    by_ldl = jnp.stack(x)

    def with_lu():
        upper, vector = (m, rhs) if system is None else system()
        full = [[upper[min(i, j)][max(i, j)] for j in range(n)] for i in range(n)]
        matrix = jnp.stack([jnp.stack(row) for row in full])
        by_lu, singular = solve_dense(matrix, jnp.stack(vector))
        return jnp.where(sound, by_ldl, by_lu), ~sound & singular

    def without_lu():
        return by_ldl, jnp.zeros((), dtype=bool)

    return jax.lax.cond(any_in_batch(~sound), with_lu, without_lu)


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
