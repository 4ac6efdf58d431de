r"""The Legendre transform, both ways, as one engine.

L → H needs the velocity from the momentum: solve $\partial L/\partial\dot q(q,\dot q)
= p$ for $\dot q$, then $H = p\cdot\dot q - L$. H → L needs the momentum from the
velocity: solve $\partial H/\partial p(q, p) = \dot q$ for $p$, then $L = p\cdot\dot q
- H$. Both are "invert the gradient of a convex function", done here once:

- a first Newton step from zero — exact when the function is quadratic (the usual
  $L = \tfrac12\dot q^T M(q)\dot q + a(q)\cdot\dot q - V$), so then it is the linear
  solve $M\dot q = p - a$ and nothing more. Whether it is quadratic is declared
  or read off the traced program (`is_at_most_quadratic`); for few variables the
  solve is then scalar arithmetic that fuses into an implicit solver's step;
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
import jax.extend as jex
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._core.precision import reachable_tolerance
from lagjax._linalg.scalarize import scalar_argument_function
from lagjax._linalg.singular_verdicts import singular_message_for
from lagjax._linalg.small_solves import (
    UNROLLED_SOLVE_LIMIT,
    solve_dense_in_step,
    solve_unrolled,
    solve_unrolled_symmetric,
)
from lagjax._linalg.window_cumsum import with_window_cumsums
from lagjax.mechanics.euler_lagrange import SCALAR_COORDINATE_LIMIT, partial_derivative

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
    check: bool | str = True,
) -> Any:
    """Solve ∇function(x) = target for x (x has the structure of `target`).

    `what` names the Hessian in the error raised when it is singular. A
    non-quadratic `function` that the damped Newton iteration cannot invert (no
    solution, or not convex there) raises an error naming the cause.

    A function that is quadratic — declared (`quadratic`) or found so by reading
    its program (`is_at_most_quadratic`) — is inverted by one linear solve, in
    scalar arithmetic for few variables. `check="nan"` returns NaN instead of
    raising (one fused select instead of a run-time branch per call, for loops
    that check their state at the end, as `Lagrangian.acceleration` does).
    """
    target_flat, unravel = ravel_pytree(target)
    start = jnp.zeros_like(target_flat)

    def flat_function(x_flat):
        return function(unravel(x_flat))

    def verdict(x, failed, message):
        if check == "nan":
            return jnp.where(failed, jnp.nan, x)
        return eqx.error_if(x, failed, message) if check else x

    quadratic = quadratic or is_at_most_quadratic(flat_function, start)
    singular_message = singular_message_for(what)
    if quadratic and target_flat.shape[0] <= SCALAR_COORDINATE_LIMIT:
        solution, singular = _quadratic_inverse_in_scalars(flat_function, target_flat)
        return unravel(verdict(solution, singular, singular_message))
    # Many variables: a chain's long cumulative sums as short windows, which XLA
    # keeps whole (GaussLegendre(2) on the 24-link pendulum, 200 steps: 39.9 →
    # 24.3 ms).
    flat_function = with_window_cumsums(flat_function, start)

    def residual(x_flat, _):
        return jax.grad(flat_function)(x_flat) - target_flat

    hessian = jax.jacfwd(residual)(start, None)
    step, singular = solve_dense_in_step(hessian, residual(start, None))
    if quadratic:
        return unravel(verdict(start - step, singular, singular_message))
    start = verdict(start, singular, singular_message)
    merit = lambda x: flat_function(x) - jnp.dot(target_flat, x)
    near = _damped_newton(merit, residual, start)
    # One more Newton step, differentiable: from the converged (stop_gradient)
    # point its derivative is −(∂r/∂x)⁻¹ ∂r/∂θ, the implicit-function theorem's.
    step, singular = solve_dense_in_step(
        jax.jacfwd(residual)(near, None), residual(near, None)
    )
    size = jax.lax.stop_gradient(jnp.max(jnp.abs(step)))
    converged = ~singular & (size <= _step_tolerance(near))
    return unravel(verdict(near - step, ~converged, _no_inverse_message(what)))


def _quadratic_inverse_in_scalars(
    function: Callable[[jax.Array], jax.Array], target: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """x = −H⁻¹(∇f(0) − p) for a quadratic f of few variables: `(x, singular)`.

    The one Newton step from zero of the general route, with every derivative a
    scalar forward-mode pass and an unrolled solve for n ≤ 3 (as in
    `euler_lagrange`): inside an implicit stage iteration the step then stays one
    fused kernel instead of an LU call per evaluation.
    """
    n = target.shape[0]
    start = jnp.zeros_like(target)
    of_scalars = scalar_argument_function(function, start)
    zero = [start[i] for i in range(n)]
    gradient = [partial_derivative(of_scalars, i) for i in range(n)]
    residual = [gradient[i](*zero) - target[i] for i in range(n)]
    # Upper triangle only (H is symmetric), mirrored for the dense solve.
    upper = {
        (i, j): partial_derivative(gradient[i], j)(*zero)
        for i in range(n)
        for j in range(i, n)
    }
    hessian = [[upper[min(i, j), max(i, j)] for j in range(n)] for i in range(n)]
    if n <= UNROLLED_SOLVE_LIMIT:
        step, singular = solve_unrolled(hessian, residual)
        return start - jnp.stack(step), singular
    step, singular = solve_unrolled_symmetric(hessian, residual)
    return start - step, singular


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
        direction, _ = solve_dense_in_step(jax.jacfwd(residual)(x, None), gradient)
        slope, value = jnp.dot(gradient, direction), merit(x)
        # Within Newton's quadratic range, φ's decrease (~|step|²) falls below φ's
        # round-off and Armijo's test fails at every length: without this, each
        # iteration then halved ~20 times for no progress and ran all
        # `_DAMPED_ITERATIONS` (relativistic particle, GaussLegendre(3), 30 steps:
        # 8 s → not done after 15 min). There a full step is trusted if finite.
        near = jnp.max(jnp.abs(direction)) <= _step_tolerance(x)

        def rejected(length):
            trial = merit(x - length * direction)
            decreased = trial <= value - 1e-4 * length * slope
            good = jnp.isfinite(trial) & (decreased | near)
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


# -- Is the function at most quadratic in its argument? ----------------------------
# Read off the traced program: a bound on the polynomial degree of every
# intermediate in x, propagated primitive by primitive. A bound (not the exact
# degree) is all that is needed, and it errs on the safe side: any operation not
# known to keep polynomials polynomial (cos, sqrt, abs, a branch on x, a loop) gives
# an unbounded degree unless none of its inputs depends on x.

_UNBOUNDED = 1_000_000
# Linear in each operand: the degree is the largest of the operands'.
_LINEAR = frozenset(
    [
        "add",
        "sub",
        "neg",
        "add_any",
        "convert_element_type",
        "copy",
        "copy_p",
        "reshape",
        "squeeze",
        "broadcast_in_dim",
        "transpose",
        "slice",
        "concatenate",
        "reduce_sum",
        "cumsum",
        "rev",
        "pad",
        "stop_gradient",
        "real",
        "imag",
        "conj",
        "split",
        "unstack",
    ]
)
_PRODUCT = frozenset({"mul", "dot_general"})
_CALLS = frozenset({"pjit", "jit", "closed_call", "core_call", "remat", "checkpoint"})
# Operands after the first are indices/positions: only the first carries degree.
_INDEXED = frozenset({"dynamic_slice", "gather", "select_and_gather_add"})


def _equation_degrees(eqn: Any, degrees: list[int]) -> list[int]:
    name = eqn.primitive.name
    count = len(eqn.outvars)
    if name in _CALLS or name in ("custom_jvp_call", "custom_vjp_call"):
        closed = eqn.params.get("jaxpr", eqn.params.get("call_jaxpr"))
        if closed is not None:
            inner = getattr(closed, "jaxpr", closed)
            return jaxpr_degrees(inner, degrees)
    rounds = name == "convert_element_type" and not jnp.issubdtype(
        eqn.params["new_dtype"], jnp.inexact
    )  # a cast to an integer truncates: not a polynomial
    if name in _LINEAR and not rounds:
        return [max(degrees, default=0)] * count
    if name in _PRODUCT:
        return [sum(degrees)] * count
    if name == "integer_pow" and eqn.params["y"] >= 0:
        return [degrees[0] * eqn.params["y"]] * count
    if name == "square":
        return [2 * degrees[0]] * count
    if name == "div" and degrees[1] == 0:
        return [degrees[0]] * count
    if name == "select_n" and degrees[0] == 0:
        return [max(degrees[1:])] * count
    if name in _INDEXED and max(degrees[1:], default=0) == 0:
        return [degrees[0]] * count
    # Anything else is polynomial only when it does not depend on x at all.
    return [0 if max(degrees, default=0) == 0 else _UNBOUNDED] * count


def jaxpr_degrees(jaxpr: Any, input_degrees: list[int]) -> list[int]:
    """Bounds on the polynomial degree of each output, given the inputs'."""
    env = dict(zip(jaxpr.invars, input_degrees))

    def degree(atom):
        # Literals and the closed-over constants do not depend on x: degree 0.
        return 0 if isinstance(atom, jex.core.Literal) else env.get(atom, 0)

    for eqn in jaxpr.eqns:
        results = _equation_degrees(eqn, [degree(v) for v in eqn.invars])
        env.update(zip(eqn.outvars, (min(d, _UNBOUNDED) for d in results)))
    return [degree(v) for v in jaxpr.outvars]


def is_at_most_quadratic(function: Callable[[jax.Array], jax.Array], x: Any) -> bool:
    """Whether `function(x)` is provably a polynomial of degree ≤ 2 in x.

    False means "not proven" (e.g. `jnp.sqrt(1 - x @ x)`, or `x**2` written as
    `jnp.power(x, 2.0)`); the caller then takes the general route, which gives the
    same result for a quadratic function, only slower.
    """
    closed = jax.make_jaxpr(function)(x)
    (degree,) = jaxpr_degrees(closed.jaxpr, [1] * len(closed.jaxpr.invars))
    return degree <= 2
