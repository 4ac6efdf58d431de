r"""The Legendre transform, both ways, as one engine.

L → H needs the velocity from the momentum: solve $\partial L/\partial\dot q(q,\dot q)
= p$ for $\dot q$, then $H = p\cdot\dot q - L$. H → L needs the momentum from the
velocity: solve $\partial H/\partial p(q, p) = \dot q$ for $p$, then $L = p\cdot\dot q
- H$. Both are "invert the gradient of a convex function", done here once:

- a first Newton step from zero — exact when the function is quadratic (the usual
  $L = \tfrac12\dot q^T M(q)\dot q + a(q)\cdot\dot q - V$), so then it is the linear
  solve $M\dot q = p - a$ and nothing more;
- otherwise `optimistix.Newton` refines to tight tolerance.

A singular Hessian (a degenerate L such as one linear in q̇) raises an error instead
of returning inf/NaN. Hamilton's equations for a Legendre-transformed Lagrangian are
evaluated directly as $\dot q = \dot q(q, p)$, $\dot p = \partial L/\partial q$ at
that velocity, so no derivative is ever taken through the nonlinear solve there.

References: the course text §6.1–6.2 (Legendre transformation, eq. 6.6–6.10);
Goldstein, *Classical Mechanics* §8.1.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import optimistix as optx
from jax.flatten_util import ravel_pytree

from lagjax.precision import newton_for

from .linalg import raise_if_singular, solve_dense

_NEWTON_RTOL = 1e-13
_NEWTON_ATOL = 1e-13


def invert_gradient(
    function: Callable[[Any], jax.Array],
    target: Any,
    *,
    quadratic: bool,
    what: str,
) -> Any:
    """Solve ∇function(x) = target for x (x has the structure of `target`).

    `what` names the Hessian in the error raised when it is singular.
    """
    target_flat, unravel = ravel_pytree(target)

    def residual(x_flat, _):
        gradient = jax.grad(function)(unravel(x_flat))
        return ravel_pytree(gradient)[0] - target_flat

    start = jnp.zeros_like(target_flat)
    hessian = jax.jacfwd(residual)(start, None)
    step, singular = solve_dense(hessian, residual(start, None))
    first = raise_if_singular(start - step, singular, what)
    if quadratic:
        return unravel(first)
    solver = newton_for(first.dtype, _NEWTON_RTOL, _NEWTON_ATOL)
    solution = optx.root_find(residual, solver, first, max_steps=64)
    return unravel(solution.value)


def tree_dot(x: Any, y: Any) -> jax.Array:
    """Σ x_i y_i over all leaves of two matching pytrees."""
    products = jax.tree_util.tree_leaves(
        jax.tree_util.tree_map(lambda a, b: jnp.sum(a * b), x, y)
    )
    # Started from the first term, not a float64 zero: the sum keeps the dtype.
    return (
        jnp.asarray(sum(products[1:], start=products[0])) if products else jnp.zeros(())
    )
