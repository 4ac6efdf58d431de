r"""The Legendre transform, both ways, as one engine.

L → H needs the velocity from the momentum: solve $\partial L/\partial\dot q(q,\dot q)
= p$ for $\dot q$, then $H = p\cdot\dot q - L$. H → L needs the momentum from the
velocity: solve $\partial H/\partial p(q, p) = \dot q$ for $p$, then $L = p\cdot\dot q
- H$. Both are "invert the gradient of a convex function", done here once:

- a first Newton step from zero — exact when the function is quadratic (the usual
  $L = \tfrac12\dot q^T M(q)\dot q + a(q)\cdot\dot q - V$), so then it is the linear
  solve $M\dot q = p - a$ and nothing more;
- otherwise a *damped* Newton iteration on the convex merit function
  $\phi(x) = f(x) - p\cdot x$ (whose gradient vanishes at the solution): each
  Newton step is halved until $\phi$ is finite and decreases (Armijo's test). This
  keeps every iterate inside the domain of $f$: for the relativistic particle
  $L = -mc^2\sqrt{1 - v^2/c^2}$ with $|p| > mc$ the full first step from rest lands
  at $|v| = |p|/m > c$, where $L$ is NaN, and plain Newton fails; the damped one
  stays below $c$ and converges ($v = p/\sqrt{m^2 + p^2/c^2}$). One last plain
  Newton step from the converged point (held constant for differentiation) squares
  the error to round-off and carries the derivatives of the implicit-function
  theorem, $\mathrm d x = -(\nabla^2 f)^{-1}\,\mathrm d(\nabla f - p)$. A state the
  iteration cannot invert raises an error naming the equation and the likely
  cause.

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

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax.precision import reachable_tolerance

from .linalg import raise_if_singular, solve_dense

_NEWTON_RTOL = 1e-13
_NEWTON_ATOL = 1e-13
# Damped Newton converges quadratically once near; the halving phase far from the
# solution (|p| ≫ mc) takes about log2 of the overshoot per step.
_DAMPED_ITERATIONS = 100
_SMALLEST_DAMPING = 2.0**-40


def invert_gradient(
    function: Callable[[Any], jax.Array],
    target: Any,
    *,
    quadratic: bool,
    what: str,
) -> Any:
    """Solve ∇function(x) = target for x (x has the structure of `target`).

    `what` names the Hessian in the error raised when it is singular. A
    non-quadratic `function` that the damped Newton iteration cannot invert (no
    solution, or not convex there) raises an error naming the cause.
    """
    target_flat, unravel = ravel_pytree(target)

    def residual(x_flat, _):
        gradient = jax.grad(function)(unravel(x_flat))
        return ravel_pytree(gradient)[0] - target_flat

    start = jnp.zeros_like(target_flat)
    hessian = jax.jacfwd(residual)(start, None)
    step, singular = solve_dense(hessian, residual(start, None))
    if quadratic:
        return unravel(raise_if_singular(start - step, singular, what))
    start = raise_if_singular(start, singular, what)
    merit = lambda x: function(unravel(x)) - jnp.dot(target_flat, x)
    near = _damped_newton(merit, residual, start)
    # One more Newton step, differentiable: from the converged (stop_gradient)
    # point its derivative is −(∂r/∂x)⁻¹ ∂r/∂θ, the implicit-function theorem's.
    step, singular = solve_dense(jax.jacfwd(residual)(near, None), residual(near, None))
    size = jax.lax.stop_gradient(jnp.max(jnp.abs(step)))
    converged = ~singular & (size <= _step_tolerance(near))
    solution = eqx.error_if(near - step, ~converged, _no_inverse_message(what))
    return unravel(solution)


def _step_tolerance(x: jax.Array, *, final: bool = True) -> jax.Array:
    """The size of a Newton step from x below which x counts as converged.

    The iteration runs to round-off (`final=False`); the last step is accepted up
    to √tol, as near a domain boundary (v → c) round-off in the gradient grows.
    """
    tolerance = reachable_tolerance(_NEWTON_ATOL, x.dtype)
    return (tolerance if not final else tolerance**0.5) * (
        1 + jnp.max(jnp.abs(x), initial=0.0)
    )


def _no_inverse_message(what: str) -> str:
    gradient = "∂L/∂q̇ = p for q̇" if "L" in what else "∂H/∂p = q̇ for p"
    return (
        f"The Legendre transform failed: solving {gradient} did not converge "
        f"(damped Newton, at most {_DAMPED_ITERATIONS} steps) at this state. Either no solution "
        "exists (the momentum or velocity lies outside the range of the gradient, "
        f"e.g. |q̇| ≥ c for a relativistic H), or {what[0].lower()}{what[1:]} is not "
        "positive definite there (L or H not convex in q̇ or p). Check the state "
        "and the function's domain."
    )


def _damped_newton(merit, residual, start: jax.Array) -> jax.Array:
    """Newton on ∇φ = 0 with backtracking on φ, until a full step is below
    `_step_tolerance`, no step decreases φ, or `_DAMPED_ITERATIONS` are spent.

    Run without derivatives (`stop_gradient`): the caller's final Newton step
    carries them.
    """
    dtype = start.dtype

    def body(carry):
        x, _, k = carry
        gradient = residual(x, None)
        direction, _ = solve_dense(jax.jacfwd(residual)(x, None), gradient)
        slope, value = jnp.dot(gradient, direction), merit(x)

        def rejected(length):
            trial = merit(x - length * direction)
            good = jnp.isfinite(trial) & (trial <= value - 1e-4 * length * slope)
            return ~good & (length > _SMALLEST_DAMPING)

        length = jax.lax.while_loop(rejected, lambda a: 0.5 * a, jnp.ones((), dtype))
        small = jnp.max(jnp.abs(direction)) <= _step_tolerance(x, final=False)
        stuck = rejected(length) | ~jnp.all(jnp.isfinite(direction))
        done = small | stuck
        return jnp.where(done, x, x - length * direction), done, k + 1

    def keep_going(carry):
        _, done, k = carry
        return ~done & (k < _DAMPED_ITERATIONS)

    x, _, _ = jax.lax.while_loop(keep_going, body, (start, jnp.asarray(False), 0))
    return jax.lax.stop_gradient(x)


def tree_dot(x: Any, y: Any) -> jax.Array:
    """Σ x_i y_i over all leaves of two matching pytrees."""
    products = jax.tree_util.tree_leaves(
        jax.tree_util.tree_map(lambda a, b: jnp.sum(a * b), x, y)
    )
    # Started from the first term, not a float64 zero: the sum keeps the dtype.
    return (
        jnp.asarray(sum(products[1:], start=products[0])) if products else jnp.zeros(())
    )
