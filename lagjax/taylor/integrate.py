"""Adaptive Taylor integration of y' = f(t, y, args) from the jaxpr of f.

Each step computes the coefficients y₀..y_p of the solution through the current
point (`coefficients`), takes the step length from the last two (`step`), moves
to the step polynomial's value at h and fills every requested save time inside
the step from the same polynomial (dense output at no extra evaluation of f).
The loop is a bounded `while_loop`, so under `jax.vmap` every member takes its
own steps (the loop runs until the slowest member is done, finished members
idle). The order p is fixed for a run (it sets array shapes); the step adapts.

What works under transformations:

- `jax.jit`, `jax.vmap` over y0, args, t0, t1 and ts;
- `jax.grad` / `jax.jacrev` with respect to y0 and args (the loop is equinox's
  checkpointed `while_loop`), as long as at most `SMALL_SAVES` save times are
  requested (more use an inner `while_loop`, which reverse mode cannot enter);
- `jax.jvp` / `jax.jacfwd` with respect to y0, args and t1 with
  `forward_mode=True` (a plain `lax.while_loop`: the checkpointed loop is a
  `custom_vjp`, which forward mode cannot enter), for any number of saves.

The step length is a control decision, not part of the solution, so it is held
out of differentiation (`stop_gradient`); derivatives are those of the step
polynomials, which agree with the exact solution's to the tolerance.

References: Jorba & Zou, Experimental Mathematics 14 (2005); Biscani & Izzo,
MNRAS 504 (2021) — heyoka's adaptive Taylor integrator and its dense output.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import diffrax
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from .coefficients import graph_coefficients, lower_vector_field
from .step import horner, horner_many, order_from_tolerance, step_size

# Up to this many save times, every step fills them by one masked evaluation
# (reverse-mode differentiable); beyond, an inner loop visits only those inside
# the step.
SMALL_SAVES = 16


class RESULTS(diffrax.RESULTS):  # pyright: ignore[reportGeneralTypeIssues]
    """diffrax's result codes, and one of the Taylor integrator's own."""

    non_finite = (
        "the Taylor step produced a non-finite state (a singular vector field, "
        "a division by zero in a recurrence, or overflow)"
    )


class TaylorSolution(eqx.Module):
    """`ys[i]` is the state at `ts[i]` (NaN where the run stopped before it);
    `num_steps` counts accepted steps; `result` is a `RESULTS` code."""

    ts: jax.Array
    ys: jax.Array
    num_steps: jax.Array
    result: RESULTS
    order: int = eqx.field(static=True)


class _Carry(NamedTuple):
    t: jax.Array
    t_low: jax.Array  # t + t_low is the time in double-length arithmetic
    y: jax.Array
    ys: jax.Array
    index: jax.Array  # the next save time to fill (inner-loop saving)
    num_steps: jax.Array
    result: RESULTS


def check_tolerance(name: str, value: Any) -> float | None:
    """A positive finite float, None for a traced value; else `ValueError`."""
    try:
        number = float(value)
    except (TypeError, jax.errors.ConcretizationTypeError):
        return None
    if not (math.isfinite(number) and number > 0):
        raise ValueError(
            f"lagjax.Taylor: {name} must be a positive finite number, got {value!r}"
        )
    return number


def resolve_order(rtol: Any, atol: Any, order: int | None) -> int:
    """The Taylor order: the user's, or p = ⌈−ln(min(rtol, atol))/2 + 1⌉."""
    tolerances = [check_tolerance("rtol", rtol), check_tolerance("atol", atol)]
    if order is not None:
        if not isinstance(order, int) or order < 2:
            raise ValueError(f"lagjax.Taylor: order must be an int ≥ 2, got {order!r}")
        return order
    if None in tolerances:
        raise TypeError(
            "lagjax.Taylor: with traced rtol/atol, pass order= (the order sets "
            "array shapes, so it must be known when tracing)"
        )
    return order_from_tolerance(min(t for t in tolerances if t is not None))


def two_sum(a: jax.Array, b: jax.Array) -> tuple[jax.Array, jax.Array]:
    """s + e = a + b exactly, s = fl(a + b) (Knuth's TwoSum)."""
    s = a + b
    b_virtual = s - a
    return s, (a - (s - b_virtual)) + (b - b_virtual)


def _saver(ts: jax.Array, direction: jax.Array) -> Callable:
    """save(coeffs, t, t_low, t_new, ys, index, ok) -> (ys, index): fill ts in
    (t, t_new] if the step is accepted (`ok`)."""
    if ts.shape[0] <= SMALL_SAVES:

        def save(coeffs, t, t_low, t_new, ys, index, ok):  # pyright: ignore[reportRedeclaration]
            inside = ok & (direction * (ts - t) > 0) & (direction * (ts - t_new) <= 0)
            values = horner_many(coeffs, (ts - t) - t_low)
            return jnp.where(inside[:, None], values, ys), index

        return save

    last = ts.shape[0] - 1

    def save(coeffs, t, t_low, t_new, ys, index, ok):  # pyright: ignore[reportRedeclaration]
        def cond(c):
            i, _ = c
            return (
                ok & (i <= last) & (direction * (ts[jnp.minimum(i, last)] - t_new) <= 0)
            )

        def body(c):
            i, ys = c
            return i + 1, ys.at[i].set(horner(coeffs, (ts[i] - t) - t_low))

        index, ys = jax.lax.while_loop(cond, body, (index, ys))
        return ys, index

    return save


def taylor_integrate(
    vector_field: Callable,
    y0: Any,
    t0: Any,
    t1: Any,
    *,
    ts: Any = None,
    args: Any = None,
    rtol: Any = 1e-15,
    atol: Any = 1e-15,
    order: int | None = None,
    max_steps: int = 1_000_000,
    forward_mode: bool = False,
    unroll: bool = False,
) -> TaylorSolution:
    """Integrate y' = vector_field(t, y, args) from (t0, y0) to t1 by Taylor's
    method; y0 a flat float array. Returns the states at `ts` (default: [t1]),
    which must be ordered from t0 towards t1.

    `forward_mode=True` runs a plain `lax.while_loop`, which `jax.jvp` /
    `jax.jacfwd` can enter; the default is equinox's checkpointed loop, which
    `jax.grad` can enter. `unroll` chooses the sweep over the orders (see
    `coefficients`; unrolled compiles far longer).
    """
    p = resolve_order(rtol, atol, order)
    y0 = jnp.asarray(y0)
    if y0.ndim != 1 or not jnp.issubdtype(y0.dtype, jnp.floating):
        raise TypeError(
            f"lagjax.Taylor: y0 must be a flat float array, got {y0.shape} {y0.dtype}"
        )
    t0, t1 = jnp.asarray(t0, y0.dtype), jnp.asarray(t1, y0.dtype)
    ts = jnp.atleast_1d(jnp.asarray(t1 if ts is None else ts, y0.dtype))
    graph, leaves = lower_vector_field(vector_field, t0, y0, args)
    direction = jnp.where(t1 >= t0, 1.0, -1.0).astype(y0.dtype)
    save = _saver(ts, direction)

    def body(c: _Carry) -> _Carry:
        coeffs = graph_coefficients(graph, c.t, c.y, leaves, p, unroll=unroll)
        h = jax.lax.stop_gradient(step_size(coeffs, rtol, atol))
        # Time in double-length arithmetic (as heyoka): a rounding error in t
        # of a few ulps per step would otherwise move the end of a long run.
        remaining = direction * ((t1 - c.t) - c.t_low)
        last = h >= jax.lax.stop_gradient(remaining)
        tau = direction * jnp.where(last, remaining, h)
        t_sum, t_err = two_sum(c.t, tau)
        t_high, t_low = two_sum(t_sum, c.t_low + t_err)
        t_new = jnp.where(last, t1, t_high)
        y_new = horner(coeffs, tau)
        ok = jnp.all(jnp.isfinite(y_new))
        ys, index = save(coeffs, c.t, c.t_low, t_new, c.ys, c.index, ok)
        keep = lambda new, old: jnp.where(ok, new, old)
        return _Carry(
            t=keep(t_new, c.t),
            t_low=keep(jnp.where(last, 0.0, t_low), c.t_low),
            y=keep(y_new, c.y),
            ys=ys,
            index=index,
            num_steps=c.num_steps + ok,
            result=RESULTS.where(ok, c.result, RESULTS.non_finite),
        )

    def cond(c: _Carry) -> jax.Array:
        return (c.t != t1) & (c.result == RESULTS.successful)

    at_start = direction * (ts - t0) <= 0
    init = _Carry(
        t=t0,
        t_low=jnp.zeros_like(t0),
        y=y0,
        ys=jnp.where(
            at_start[:, None],
            y0,
            jnp.nan * jnp.ones((ts.shape[0], *y0.shape), y0.dtype),
        ),
        index=jnp.sum(at_start),
        num_steps=jnp.array(0),
        result=RESULTS.successful,  # pyright: ignore[reportArgumentType]
    )
    final = eqxi.while_loop(
        cond,
        body,
        init,
        max_steps=max_steps,
        kind="lax" if forward_mode else "checkpointed",
        buffers=None if ts.shape[0] <= SMALL_SAVES else (lambda c: c.ys),
    )
    result = RESULTS.where(
        (final.t != t1) & (final.result == RESULTS.successful),
        RESULTS.max_steps_reached,  # pyright: ignore[reportArgumentType]
        final.result,
    )
    return TaylorSolution(
        ts=ts, ys=final.ys, num_steps=final.num_steps, result=result, order=p
    )
