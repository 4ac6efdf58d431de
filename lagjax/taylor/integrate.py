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

Two things a run reads off its step polynomials besides the saves, each paid for
only when asked for: terminal events (`event`, `lagjax.taylor.events`: the
conditions sampled on every step, the crossing located on the step that crossed)
and dense output (`dense`, `lagjax.taylor.dense`: every step's polynomial kept).

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
from .dense import DenseBuffer, TaylorDense, empty_buffer, keep_step
from .events import StepEvent, Watch, first_crossing, start_watch, watch_step
from .step import (
    compensated_advance,
    horner,
    horner_many,
    order_from_tolerance,
    step_size,
    two_sum,
)

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
    `num_steps` counts accepted steps; `result` is a `RESULTS` code.

    With an `event`: `event_mask` says which condition ended the run
    (`RESULTS.event_occurred`); the saves after the event are t = inf, y = inf,
    and without `ts` the one save is the state at the event. With `dense=True`:
    `dense.evaluate(t)` is the state at any t of the run."""

    ts: jax.Array
    ys: jax.Array
    num_steps: jax.Array
    result: RESULTS
    order: int = eqx.field(static=True)
    event_mask: jax.Array | None = None
    dense: TaylorDense | None = None


class _Carry(NamedTuple):
    t: jax.Array
    t_low: jax.Array  # t + t_low is the time in double-length arithmetic
    y: jax.Array
    y_low: jax.Array  # y + y_low: the state with compensated summation
    ys: jax.Array
    index: jax.Array  # the next save time to fill (inner-loop saving)
    num_steps: jax.Array
    result: RESULTS
    watch: Watch | None = None  # with an event
    dense: DenseBuffer | None = None  # with dense output


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
    event: StepEvent | None = None,
    dense: bool = False,
) -> TaylorSolution:
    """Integrate y' = vector_field(t, y, args) from (t0, y0) to t1 by Taylor's
    method; y0 a flat float array. Returns the states at `ts` (default: [t1]),
    which must be ordered from t0 towards t1.

    `forward_mode=True` runs a plain `lax.while_loop`, which `jax.jvp` /
    `jax.jacfwd` can enter; the default is equinox's checkpointed loop, which
    `jax.grad` can enter. `unroll` chooses the sweep over the orders (see
    `coefficients`; unrolled compiles far longer). `event` (a `StepEvent` on the
    flat state) ends the run where one of its conditions crosses zero
    (`lagjax.taylor.events`); `dense=True` keeps every step's polynomial in a
    buffer of `max_steps` rows (`lagjax.taylor.dense`). Neither costs anything
    per step when not asked for.
    """
    p = resolve_order(rtol, atol, order)
    y0 = jnp.asarray(y0)
    if y0.ndim != 1 or not jnp.issubdtype(y0.dtype, jnp.floating):
        raise TypeError(
            f"lagjax.Taylor: y0 must be a flat float array, got {y0.shape} {y0.dtype}"
        )
    t0, t1 = jnp.asarray(t0, y0.dtype), jnp.asarray(t1, y0.dtype)
    final_only = ts is None
    ts = jnp.atleast_1d(jnp.asarray(t1 if ts is None else ts, y0.dtype))
    # A scalar graph where f allows: its orders then run on the tape (`tape`).
    graph, leaves = lower_vector_field(vector_field, t0, y0, args, scalar=True)
    direction = jnp.where(t1 >= t0, 1.0, -1.0).astype(y0.dtype)
    save = _saver(ts, direction)

    def body(c: _Carry) -> _Carry:
        coeffs = graph_coefficients(graph, c.t, c.y, leaves, p, unroll=unroll)
        h = jax.lax.stop_gradient(step_size(coeffs, rtol, atol))
        tau, t_new, t_low, last = _advance_time(c.t, c.t_low, h, t1, direction)
        y_new, y_low = compensated_advance(coeffs, tau, c.y_low)
        ok = jnp.all(jnp.isfinite(y_new))
        ys, index = save(coeffs, c.t, c.t_low, t_new, c.ys, c.index, ok)
        keep = lambda new, old: jnp.where(ok, new, old)
        return _Carry(
            t=keep(t_new, c.t),
            t_low=keep(jnp.where(last, 0.0, t_low), c.t_low),
            y=keep(y_new, c.y),
            y_low=keep(y_low, c.y_low),
            ys=ys,
            index=index,
            num_steps=c.num_steps + ok,
            result=RESULTS.where(ok, c.result, RESULTS.non_finite),
            watch=None
            if event is None or c.watch is None
            else watch_step(event, c.watch, coeffs, c.t, c.t_low, tau, args, ok),
            dense=None
            if c.dense is None
            else keep_step(c.dense, c.num_steps, c.t, c.t_low, coeffs),
        )

    def cond(c: _Carry) -> jax.Array:
        going = (c.t != t1) & (c.result == RESULTS.successful)
        return going if c.watch is None else going & ~jnp.any(c.watch.fired)

    init = _Carry(
        t=t0,
        t_low=jnp.zeros_like(t0),
        y=y0,
        y_low=jnp.zeros_like(y0),
        **_saves_at_start(ts, t0, y0, direction),
        num_steps=jnp.array(0),
        result=RESULTS.successful,  # pyright: ignore[reportArgumentType]
        watch=None
        if event is None
        else start_watch(event, vector_field, t0, y0, args, p),
        dense=empty_buffer(max_steps, p, y0, direction) if dense else None,
    )
    final = eqxi.while_loop(
        cond,
        body,
        init,
        max_steps=max_steps,
        kind="lax" if forward_mode else "checkpointed",
        buffers=_buffers(ts.shape[0] > SMALL_SAVES, dense),
    )
    solution = TaylorSolution(ts=ts, ys=final.ys, num_steps=final.num_steps,
                              result=_final_result(final, t1), order=p)  # fmt: skip
    end = t1
    if event is not None:
        assert final.watch is not None
        solution, end = _end_at_event(
            solution, event, final.watch, args, direction, final_only
        )
    if final.dense is not None:
        solution = _with_dense(solution, final, t0, t1, end, direction)
    return solution


def _advance_time(
    t: jax.Array, t_low: jax.Array, h: jax.Array, t1: jax.Array, direction: jax.Array
) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """`(tau, t_new, t_low_new, last)`: a step of `h` towards `t1`, the last one
    cut to land on it. Time is kept in double-length arithmetic (t + t_low, as
    heyoka): a rounding error in t of a few ulps per step would otherwise move
    the end of a long run."""
    remaining = direction * ((t1 - t) - t_low)
    last = h >= jax.lax.stop_gradient(remaining)
    tau = direction * jnp.where(last, remaining, h)
    t_sum, t_err = two_sum(t, tau)
    t_high, t_low_new = two_sum(t_sum, t_low + t_err)
    return tau, jnp.where(last, t1, t_high), t_low_new, last


def _saves_at_start(ts: jax.Array, t0: jax.Array, y0: jax.Array, direction) -> dict:
    """The save slots (y0 at the save times at or before t0, NaN for the rest)
    and the index of the first save still ahead."""
    at_start = direction * (ts - t0) <= 0
    unreached = jnp.nan * jnp.ones((ts.shape[0], *y0.shape), y0.dtype)
    return dict(ys=jnp.where(at_start[:, None], y0, unreached),
                index=jnp.sum(at_start))  # fmt: skip


def _final_result(final: _Carry, t1: jax.Array) -> Any:
    """The loop's result code: `max_steps_reached` for a run that stopped short
    of t1 without a failure or an event (which ends a run early, successfully)."""
    stopped = (final.t != t1) & (final.result == RESULTS.successful)
    if final.watch is not None:
        stopped = stopped & ~jnp.any(final.watch.fired)
    return RESULTS.where(
        stopped,
        RESULTS.max_steps_reached,  # pyright: ignore[reportArgumentType]
        final.result,
    )


def _with_dense(
    solution: TaylorSolution, final: _Carry, t0, t1, event_time, direction
) -> TaylorSolution:
    """The kept polynomials, over [t0, where the run ended: t1, the event, or
    the last good step]."""
    assert final.dense is not None
    result = solution.result
    end = jnp.where(result == RESULTS.successful, t1, final.t)
    end = jnp.where(result == RESULTS.event_occurred, event_time, end)
    return eqx.tree_at(
        lambda s: s.dense,
        solution,
        TaylorDense(final.dense, final.num_steps, t0, end, direction),
        is_leaf=lambda x: x is None,
    )


def _buffers(many_saves: bool, dense: bool) -> Callable | None:
    """The carry's arrays written one row per step, for the checkpointed loop."""
    if not (many_saves or dense):
        return None
    return lambda c: tuple(
        ([c.ys] if many_saves else []) + (list(c.dense) if dense else [])
    )


def _end_at_event(
    solution: TaylorSolution,
    event: StepEvent,
    watch: Watch,
    args: Any,
    direction: jax.Array,
    final_only: bool,
) -> tuple[TaylorSolution, jax.Array]:
    """The run ended by an event: its time and state located on the last step's
    polynomial, the saves after it marked inf (diffrax's convention), or, with no
    save times asked for, the one save moved to the event. Also the event time."""
    crossing = first_crossing(event, watch, args, direction)
    t_event = watch.t + (watch.t_low + crossing.tau)
    y_event = horner(watch.coeffs, crossing.tau)
    occurred = crossing.occurred & (solution.result == RESULTS.successful)
    ts, ys = solution.ts, solution.ys
    if final_only:
        ts = jnp.where(occurred, t_event, ts)
        ys = jnp.where(occurred, y_event, ys)
    else:
        after = occurred & (direction * (ts - t_event) > 0)
        ts = jnp.where(after, jnp.inf, ts)
        ys = jnp.where(after[:, None], jnp.inf, ys)
    result = RESULTS.where(
        occurred,
        RESULTS.event_occurred,  # pyright: ignore[reportArgumentType]
        solution.result,
    )
    solution = eqx.tree_at(
        lambda s: (s.ts, s.ys, s.result, s.event_mask),
        solution,
        (ts, ys, result, crossing.mask & occurred),
        is_leaf=lambda x: x is None,
    )
    return solution, t_event
