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
- `solve_symmetric_system` (and `solve_symmetric` for a matrix at hand) works on
  arrays of any size for a symmetric M that is usually positive definite:
  Cholesky (half the work of LU, and what a hand-written solver of a physical M
  uses), with LU as the fallback for the rare indefinite or ill-conditioned M —
  decided per batch under `vmap` (see its docstring).

All return a flag that is true when M is numerically singular; callers turn it into
a run-time error with `singular_verdicts.raise_if_singular` instead of passing on
inf/NaN.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np

from lagjax._core.batch_branch import any_in_batch
from lagjax._linalg.loop_factorizations import (
    LOOP_FACTORIZATION_LIMIT,
    cholesky_by_columns,
    solve_by_cholesky_factor,
    solve_by_pivoted_lu,
)
from lagjax._linalg.marked_solves import marked_solve, solves_marked
from lagjax._linalg.unrolled_ldl import (
    SINGULAR_EPS_FACTOR,
    ldl_factor_unrolled,
    ldl_solve_unrolled,
    pivots_sound,
)

UNROLLED_SOLVE_LIMIT = 3


def _singular_threshold(n: int, dtype) -> float:
    return SINGULAR_EPS_FACTOR * n * float(jnp.finfo(dtype).eps)


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
    a singular matrix makes x NaN: one scalar select per entry, after the
    division, off the determinant's path to it (a select on the determinant
    lengthened the step's dependency chain).
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
    x = [sum(adj[i][j] * rhs[j] for j in range(n)) / det for i in range(n)]
    if poison:
        x = [jnp.where(singular, jnp.nan, xi) for xi in x]
    return x, singular


def pivot_verdict(pivots: jax.Array) -> jax.Array:
    """Whether the LU pivots (the diagonal of U) say singular: the smallest
    against the largest."""
    pivot_sizes = jnp.abs(pivots)
    largest = jnp.max(pivot_sizes, axis=-1)
    threshold = _singular_threshold(pivots.shape[-1], pivots.dtype)
    return (largest == 0) | (jnp.min(pivot_sizes, axis=-1) <= threshold * largest)


def _lu_verdict(m: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """LU factors of m and its singular flag (`pivot_verdict`)."""
    lu, pivots = jsl.lu_factor(m)
    return lu, pivots, pivot_verdict(jnp.diagonal(lu))


def _solve_dense_in_kernel(m: jax.Array, rhs: jax.Array):
    """`solve_dense`, by XLA loops up to `LOOP_FACTORIZATION_LIMIT` unknowns."""
    if m.shape[-1] > LOOP_FACTORIZATION_LIMIT:
        return solve_dense(m, rhs)
    x, pivots = solve_by_pivoted_lu(m, rhs)
    return x, pivot_verdict(pivots)


def solve_dense_in_step(m: jax.Array, rhs: jax.Array) -> tuple[jax.Array, jax.Array]:
    """`solve_dense` for a system solved at every step (vector `rhs`): on CPU by
    XLA loops up to `LOOP_FACTORIZATION_LIMIT` unknowns, which stay inside the
    step's kernel (`loop_factorizations`); elsewhere, and above, LAPACK."""
    return jax.lax.platform_dependent(
        m, rhs, cpu=_solve_dense_in_kernel, default=solve_dense
    )


def solve_dense(m: jax.Array, rhs: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Solve m x = rhs by LU with partial pivoting. Returns `(x, singular)`."""
    lu, pivots, singular = _lu_verdict(m)
    return jsl.lu_solve((lu, pivots), rhs), singular


def _factor_verdict(factor: jax.Array, judge: bool) -> jax.Array:
    """Whether a Cholesky factor is used: it exists and, when `judge`, no squared
    diagonal entry (a pivot of LDLᵀ) is relatively tiny."""
    if not judge:
        # A failed factorization is NaN from its failing column on (LAPACK's
        # entirely): the last diagonal entry tells.
        return jnp.isfinite(factor[..., -1, -1])
    squared_pivots = jnp.diagonal(factor, axis1=-2, axis2=-1) ** 2
    threshold = _singular_threshold(factor.shape[-1], factor.dtype)
    # False for NaN, zero or relatively tiny pivots: then LU solves and judges.
    return jnp.min(squared_pivots, axis=-1) > threshold * jnp.max(
        squared_pivots, axis=-1
    )


# Batched factorizations up to this much work (members × n³) stay one LAPACK call;
# above it they are mapped per member (`_cholesky_per_member`). It is the largest
# size measured hang-free many times here (n = 16 ×64).
BATCHED_CHOLESKY_WORK_LIMIT = 64 * 16**3


@jax.custom_batching.custom_vmap
def _cholesky_per_member(m: jax.Array) -> jax.Array:
    """The Cholesky factor of m (`_lapack_cholesky`); under `vmap` beyond
    `BATCHED_CHOLESKY_WORK_LIMIT`, one LAPACK call per member (`lax.map`)
    instead of one batched call.

    Why: jaxlib 0.10.2's batched CPU Cholesky splits a large batch over XLA's
    intra-op thread pool and waits for it; called from a thread of that pool —
    which happens when XLA has split the step's large kernels over threads — two
    such calls can wait on each other for ever. Measured here in an RK4 scan of
    the n-link pendulum: n = 24 ×64, n = 16 ×512 and n = 12 ×1024 hung in 14 of
    15 tries (the hand-written Cholesky twin too, at n = 16 ×512), in none of 14
    mapped per member; n ≤ 16 ×64 never hung in dozens of runs. The map costs
    12–20 % of the batched step (n = 8 to 16 ×64), hence only above the limit.
    Only on CPU (`lax.platform_dependent`): on a GPU (H100, jax 0.11.2) the map
    serialises the members, 1230× the batched factorization at n = 8 ×4096.
    """
    return _lapack_cholesky(m)


def _lapack_cholesky(m: jax.Array) -> jax.Array:
    """LAPACK's lower Cholesky factor of the symmetric m, read from m's upper
    triangle: the factor of mᵀ, which is m's. XLA hands LAPACK column-major
    matrices, and m's transpose already is one, where m itself took a transposing
    copy at every call: that copy cost the 24-link pendulum's RK4 step 20 %
    (1.21 → 1.03× the hand-written Cholesky twin, which factors mᵀ too, as
    `jax.scipy.linalg.cho_factor` does for an upper factor)."""
    return jax.lax.linalg.cholesky(jnp.swapaxes(m, -1, -2), symmetrize_input=False)


def _upper_triangular_solve(factor: jax.Array, rhs: jax.Array) -> jax.Array:
    """x with L Lᵀ x = rhs for LAPACK's lower factor L, handed over as the upper
    factor Lᵀ (a transpose XLA does without a copy, see `_lapack_cholesky`)."""
    return jsl.cho_solve((jnp.swapaxes(factor, -1, -2), False), rhs)


@_cholesky_per_member.def_vmap
def _cholesky_per_member_rule(axis_size, in_batched, m):
    if not in_batched[0]:
        return _cholesky_per_member(m), False
    batched = _lapack_cholesky
    if axis_size * m.shape[-1] ** 3 <= BATCHED_CHOLESKY_WORK_LIMIT:
        return batched(m), True
    # The hang is the CPU backend's: GPUs keep one batched call, which a map of
    # thousands of tiny factorizations would serialise.
    mapped = functools.partial(jax.lax.map, _cholesky_per_member)
    return jax.lax.platform_dependent(m, cpu=mapped, default=batched), True


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _cholesky_solve(
    m: jax.Array, rhs: jax.Array, judge: bool
) -> tuple[jax.Array, jax.Array]:
    """`(x, sound)`: x from the Cholesky factor of m (one triangle read), and
    whether that factor is to be used (`_factor_verdict`). Undifferentiated runs
    factor by XLA loops up to `LOOP_FACTORIZATION_LIMIT` coordinates
    (`loop_factorizations`), by LAPACK above, per member for large batches
    (`_cholesky_per_member`); the derivative rule keeps JAX's batched
    factorization, which reverse mode can differentiate again."""
    if m.shape[-1] <= LOOP_FACTORIZATION_LIMIT:
        factor = cholesky_by_columns(m)
        x = solve_by_cholesky_factor(factor, rhs)
    else:
        factor = _cholesky_per_member(m)
        x = _upper_triangular_solve(factor, rhs)
    return x, _factor_verdict(factor, judge)


@_cholesky_solve.defjvp
def _cholesky_solve_jvp(judge: bool, primals, tangents) -> tuple[Any, Any]:
    # dx = m⁻¹(d rhs − dm x), with the factor already at hand (JAX's own Cholesky
    # derivative would cost two triangular solves with a matrix).
    m, rhs = primals
    dm, drhs = tangents
    if m.shape[-1] <= LOOP_FACTORIZATION_LIMIT:
        factor = cholesky_by_columns(m)
        solve = solve_by_cholesky_factor
    else:
        factor = _lapack_cholesky(m)
        solve = _upper_triangular_solve

    sound = _factor_verdict(factor, judge)
    # Where LU takes over, x and dx are discarded; they must still not be NaN,
    # or reverse mode would multiply the discarded NaN by a zero cotangent.
    identity = jnp.broadcast_to(jnp.eye(m.shape[-1], dtype=m.dtype), m.shape)
    safe = jnp.where(sound[..., None, None], factor, identity)
    x = solve(safe, rhs)
    dx = solve(safe, drhs - dm @ x)
    no_tangent = np.zeros(sound.shape, dtype=jax.dtypes.float0)
    return (x, sound), (dx, no_tangent)


def solve_symmetric_system(
    system: Callable[[], tuple[jax.Array, jax.Array]], *, judge: bool = True
) -> tuple[jax.Array, jax.Array]:
    r"""Solve m x = rhs for the symmetric `(m, rhs) = system()`, by Cholesky when m
    is positive definite; LU with partial pivoting only where it is not.

    With `judge` (the default), the Cholesky factor is used when it exists and
    no squared diagonal entry of it (a pivot of $LDL^T$) is below `solve_dense`'s
    relative threshold; otherwise (m indefinite, singular or nearly so) LU solves
    and judges, so an indefinite but nonsingular m is solved exactly and
    `singular` is `solve_dense`'s verdict. Without `judge` — for callers that
    discard the verdict, like an integration loop — LU is used only where the
    factorization failed (m not positive definite), decided by one entry of the
    factor, and a nearly singular positive definite m is not flagged.

    Up to `LOOP_FACTORIZATION_LIMIT` unknowns both factorizations are XLA loops
    (`loop_factorizations`), which XLA compiles into the surrounding step (n-link
    pendulum in an RK4 scan, n = 8 / 16: one trajectory 1.38 / 1.50× the
    hand-written LAPACK twin → 0.64 / 0.77×, ×64 1.51 / 1.21× → 0.92 / 1.05×),
    at the price of compile time (that scan: 1.7 / 2.6 s one trajectory and
    3.9 / 5.0 s ×64, against the twin's 0.3–0.5 s).
    Above it they are LAPACK's.

    The fallback is a `lax.cond` whose predicate is reduced over the batch under
    `vmap` (`any_in_batch`), so LU runs only when some member needs it, and then
    only those members take its answer. With LAPACK its branch calls `system`
    again rather than taking m as an operand: XLA then keeps m's fused
    computation feeding the factorization as it is, where an operand shared with
    the branch made it recompute m's last fusion (n-link pendulum, n = 8 and 16,
    `benchmarks/derivation_overhead.py`: 1.53 → 1.38× and 1.52 → 1.36× the
    hand-written twin, one trajectory).

    Derivatives: $dx = m^{-1}(d\,\mathrm{rhs} - dm\,x)$ with the Cholesky factor
    (a custom JVP, linear in the tangents, so reverse mode transposes it), by the
    same loops up to the limit (tangents through an RK4 scan of the n-link
    pendulum, against the LAPACK twin's: n = 8 one trajectory 0.87 → 0.38×,
    ×64 1.10 → 0.52×, n = 16 1.17 → 0.24×; gradients 2.96 → 0.50×, 2.21 →
    1.91×, 3.01 → 1.29×); JAX's own rules through LU where LU answers.

    All of this is the CPU's program. Other backends (`lax.platform_dependent`)
    solve by LU with partial pivoting alone, `solve_dense`, whose verdict is
    always judged: on a GPU every `lax.cond` waits for its predicate to reach the
    host, and that wait dominated the step. H100, jax 0.11.2, n-link pendulum in
    an RK4 scan against the hand-written Cholesky twin, n = 8 / 16 / 32: 4096
    trajectories 1.48 / 1.71 / 1.75× with the branch, 0.95 / 1.47 / 1.76× by LU
    alone; one trajectory 1.71 / 1.81 / 1.75× and 1.58 / 1.54 / 2.11× (a single
    LU is slow there; one trajectory runs about 20× faster on the CPU anyway).
    Under `marked_solves.marking_solves` (a trace for the Taylor graph) the solve
    is one named call of `solve_dense`, which that graph reads as one operation.
    Returns `(x, singular)`.
    """
    m, rhs = system()
    if solves_marked():
        return marked_solve(solve_dense, m, rhs)

    def cholesky_with_lu_fallback(m, rhs):
        x, sound = _cholesky_solve(m, rhs, judge)

        def with_lu():
            # In-kernel solves take m as it is: deriving it again doubled the
            # compile time of the kernel, at the same run time.
            in_kernel = m.shape[-1] <= LOOP_FACTORIZATION_LIMIT
            m_lu, rhs_lu = (m, rhs) if in_kernel else system()
            by_lu, singular = _solve_dense_in_kernel(m_lu, rhs_lu)
            return jnp.where(sound[..., None], x, by_lu), ~sound & singular

        def without_lu():
            return x, jnp.zeros(sound.shape, dtype=bool)

        return jax.lax.cond(any_in_batch(~sound), with_lu, without_lu)

    return jax.lax.platform_dependent(
        m, rhs, cpu=cholesky_with_lu_fallback, default=solve_dense
    )


def solve_symmetric(m: jax.Array, rhs: jax.Array) -> tuple[jax.Array, jax.Array]:
    """`solve_symmetric_system` for a matrix and right-hand side at hand (judged).
    Returns `(x, singular)`."""
    return solve_symmetric_system(lambda: (m, rhs))


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
    batch under `vmap`, as in `solve_symmetric`. Returns `(x, singular)`. On CPU
    that LU runs as XLA loops (`solve_dense_in_step`): a LAPACK call in the
    branch, even never taken, kept the step from compiling as one kernel
    (n-link pendulum in an RK4 scan, n = 6: 0.75 → 0.34× the Cholesky twin for
    one trajectory, 2.25 → 1.16–1.23× ×64).

    Under `marked_solves.marking_solves` the solve is one named call, as in
    `solve_symmetric_system`.

    `system`, when given, returns `(m, rhs)` again: the fallback branch calls it
    instead of taking the n² + n scalars as its operands, so that its operands are
    the (few) inputs they were computed from. Handing the branch the scalars made
    XLA split the fused step around them: the n-link pendulum's step at n = 6 went
    from 0.27× to 1.9× its hand-written twin (`benchmarks/derivation_overhead.py`).
    """
    n = len(rhs)
    if solves_marked():  # as `solve_symmetric_system` (`marked_solves`)
        full = [[m[min(i, j)][max(i, j)] for j in range(n)] for i in range(n)]
        matrix = jnp.stack([jnp.stack(row) for row in full])
        return marked_solve(solve_dense, matrix, jnp.stack(rhs))
    factor = ldl_factor_unrolled(m)
    sound = pivots_sound(factor)
    by_ldl = jnp.stack(ldl_solve_unrolled(factor, rhs))

    def with_lu():
        upper, vector = (m, rhs) if system is None else system()
        full = [[upper[min(i, j)][max(i, j)] for j in range(n)] for i in range(n)]
        matrix = jnp.stack([jnp.stack(row) for row in full])
        by_lu, singular = solve_dense_in_step(matrix, jnp.stack(vector))
        return jnp.where(sound, by_ldl, by_lu), ~sound & singular

    def without_lu():
        return by_ldl, jnp.zeros((), dtype=bool)

    return jax.lax.cond(any_in_batch(~sound), with_lu, without_lu)
