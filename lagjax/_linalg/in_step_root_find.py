"""Newton's method inside an integration step, without leaving the step's kernel.

Some steps solve a small nonlinear system at every step: the variational midpoint
step its discrete Euler–Lagrange equation, the projection onto constraints its
position equations (when the unrolled simplified Newton did not converge). They
run `optimistix.Newton`, whose linear solves default to lineax's LU — a LAPACK
call, which on CPU XLA cannot compile into the loop body around it, so every step
was dispatched piece by piece. `InStepLU` is a lineax solver that factors the
materialised Jacobian the way the step's own arithmetic is compiled: unrolled
into scalars for a few unknowns (`unrolled_lu`, what a hand-written Cramer's rule
costs), as XLA loops up to `LOOP_FACTORIZATION_LIMIT`, LAPACK above and on other
backends (`linalg.solve_dense_in_step`).

Measured (`benchmarks/implicit_overhead.py`, double pendulum, one trajectory,
2-core CPU): `VariationalMidpoint` 2.99 µs/step with lineax's LU, 0.80 with
conjugate gradients on the normal equations (this module's previous solve), see
the README for the figure with `InStepLU`.

References: Golub & Van Loan, *Matrix Computations*, 4th ed., Alg. 3.4.1;
Kelley, *Solving Nonlinear Equations with Newton's Method*, SIAM (2003), ch. 1.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import lineax as lx
import lineax.internal as lxi
import optimistix as optx

from lagjax._linalg.small_solves import pivot_verdict, solve_dense_in_step
from lagjax._linalg.unrolled_lu import UNROLLED_LU_LIMIT, lu_solve_unrolled

_State = tuple[jax.Array, Any, Any]


def _solve_materialised(matrix: jax.Array, rhs: jax.Array):
    """`(x, singular)` for a square `matrix`, compiled as the step around it is."""
    n = rhs.shape[-1]
    if n > UNROLLED_LU_LIMIT:
        return solve_dense_in_step(matrix, rhs)
    entries = [[matrix[i, j] for j in range(n)] for i in range(n)]
    x, pivots = lu_solve_unrolled(entries, [rhs[i] for i in range(n)])
    return jnp.stack(x), pivot_verdict(jnp.stack(pivots))


class InStepLU(lx.AbstractLinearSolver[_State]):
    """LU with partial pivoting of the materialised operator, unrolled or as XLA
    loops on CPU (see the module docstring); square nonsingular operators only.
    A numerically singular operator (`linalg.pivot_verdict`) is reported as
    `lineax.RESULTS.singular`."""

    def init(self, operator: lx.AbstractLinearOperator, options: dict[str, Any]):
        del options
        if operator.in_size() != operator.out_size():
            raise ValueError("InStepLU solves square systems only")
        structures = lxi.pack_structures(operator)
        return operator.as_matrix(), structures, eqxi.Static(False)

    def compute(self, state: _State, vector: Any, options: dict[str, Any]):
        del options
        matrix, structures, transposed = state
        if transposed.value:
            matrix = matrix.T
        rhs = lxi.ravel_vector(vector, structures)
        solution, singular = _solve_materialised(matrix, rhs)
        result = lx.RESULTS.where(singular, lx.RESULTS.singular, lx.RESULTS.successful)
        return lxi.unravel_solution(solution, structures), result, {}

    def transpose(self, state: _State, options: dict[str, Any]):
        del options
        matrix, structures, transposed = state
        flipped = lxi.transpose_packed_structures(structures)
        return (matrix, flipped, eqxi.Static(not transposed.value)), {}

    def conj(self, state: _State, options: dict[str, Any]):
        del options
        matrix, structures, transposed = state
        return (matrix.conj(), structures, transposed), {}

    def assume_full_rank(self) -> bool:
        return True


def root_find_in_step(
    residual: Callable[[jax.Array, Any], jax.Array],
    newton: optx.Newton,
    guess: jax.Array,
    max_steps: int,
) -> tuple[jax.Array, optx.RESULTS]:
    """`optimistix.root_find` by `newton`'s tolerances with `InStepLU` as the
    linear solver (no throw), for a solve inside a step: `(value, result)`.

    Newton's own stopping test decides the accuracy; a singular Jacobian fails
    the iteration, which the caller reports.
    """
    in_step = optx.Newton(rtol=newton.rtol, atol=newton.atol, linear_solver=InStepLU())
    solution = optx.root_find(
        residual, in_step, guess, max_steps=max_steps, throw=False
    )
    return solution.value, solution.result
