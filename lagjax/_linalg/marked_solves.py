"""Linear solves that a jaxpr reader can recognise as one operation.

A Taylor method needs the coefficients of x(τ) = M(τ)⁻¹ b(τ). Read off the
jaxpr of a Cholesky or LU factorization, the solve is hundreds of scalar
operations inside XLA loops (`scan`) and a pivoted fallback, each with its own
recurrence. As one operation it has a short recurrence of its own: from M x = b,

    M₀ xₖ = bₖ − Σ_{j=1}^{k} Mⱼ xₖ₋ⱼ,

one solve with the order-0 matrix per order (`lagjax.taylor.recurrences`).

While `marking_solves()` is active — only around the trace of a vector field
that `lagjax.taylor` lowers — `solve_symmetric_system` traces its solve as a
`jax.jit` call named `MARKED_SOLVE_NAME` (`marked_solve`), which the Taylor
graph does not enter. Evaluated as it stands (outside the graph, or if a trace
made under the flag is reused), the call is the solve it wraps, so nothing
depends on the mark being read.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
from collections.abc import Callable, Iterator

import jax

_MARKING = contextvars.ContextVar("lagjax_marking_solves", default=False)


@contextlib.contextmanager
def marking_solves() -> Iterator[None]:
    """Within this block, symmetric solves are traced as `marked_solve` calls."""
    token = _MARKING.set(True)
    try:
        yield
    finally:
        _MARKING.reset(token)


def solves_marked() -> bool:
    """Whether `marking_solves` is active."""
    return _MARKING.get()


@functools.partial(jax.jit, static_argnums=0)
def marked_solve(
    solve: Callable[[jax.Array, jax.Array], tuple[jax.Array, jax.Array]],
    m: jax.Array,
    rhs: jax.Array,
) -> tuple[jax.Array, jax.Array]:
    """`solve(m, rhs)` → `(x, singular)`, as one named call (module docstring)."""
    return solve(m, rhs)


MARKED_SOLVE_NAME = "marked_solve"  # the call's name in a jaxpr
