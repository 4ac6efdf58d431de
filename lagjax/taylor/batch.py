"""Adaptive Taylor integration of a batch of initial conditions, batch-native.

`jax.vmap` of the one-trajectory integrator (`integrate`) batches a `while_loop`
with a step count per member: XLA runs it until the slowest member is done, moves
the batch to the front of every array (the Cauchy sums then reduce along the
minor axis) and guards every update of the carry with a select. This module
writes the batch loop directly instead, as heyoka's batch mode does:

- one Taylor order p for the whole batch (it sets the shapes), a step size hᵦ
  per member from its own last two coefficients (Jorba & Zou's rule, `step`);
- the batch on the last (minor) axis of every value: the state is (n, B), a
  series (p + 1, *shape, B), so each elementary operation of every recurrence is
  one vector operation over the members (SIMD on a CPU, a wide kernel on a GPU);
- one `while_loop` over steps per tile of members until every member of the
  tile reached t1; a finished member takes zero steps (τᵦ = 0) and keeps its
  state. Tiles run in turn (`lax.map`): a member waits only for its tile's
  slowest. The tile depends on where the loop runs (`default_tile`): on a CPU
  32 members, so a tile's tape stays in cache (double pendulum ×1024 to t = 10
  at tol 1e-12, one pinned core, tiles timed in turn in one run: tiles of 8, 16,
  24, 32, 48, 64 at 2.22, 2.03, 2.09, 1.99, 2.13, 2.14× heyoka's batch mode; the
  members wait for their tile's slowest: 1.1, 2.2, 4.3 % more member-steps than
  taken at 16, 32, 64, θ₁ in order); on
  a GPU or TPU the whole batch up to `ACCELERATOR_TILE` members, since a kernel
  over 32 lanes leaves the device idle (double pendulum ×10⁴ to t = 10 at 1e-12
  on an H200: tiles of 32, 631 members/s; the whole batch, 7.4e4/s);
- the coefficients by the scalar graph on a tape (`tape`): per order, the inner
  Cauchy sums of every operation, then O(1) per operation. A tile's loop
  carries its tape from step to step, so no step zeroes a fresh one.

The cost per step is that of one trajectory with every scalar replaced by a
vector of the tile, so per member it falls with the tile until the vector unit
(or the cache) is full. It is a forward computation: for gradients use `jax.vmap` of
`taylor_integrate`, which reverse mode can enter.

References: Biscani & Izzo, "Revisiting high-order Taylor methods for
astrodynamics and celestial mechanics", MNRAS 504 (2021), §5 (batch mode);
Jorba & Zou, Experimental Mathematics 14 (2005).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax.core import Tracer

from .coefficients import graph_coefficients, lower_vector_field
from .integrate import (
    RESULTS,
    SMALL_SAVES,
    TaylorSolution,
    resolve_order,
)
from .step import compensated_advance, horner, step_size, two_sum
from .tape import supports, tape_shape

# Members per tile on a CPU: the tape of a tile stays in cache (module docstring).
CPU_TILE = 32
# Members per tile at most on a GPU or TPU. A tile's loop holds the series of
# every tape value, (p + 1) × tile numbers each, and past a few 10⁵ members the
# throughput falls (double pendulum ×10⁶ to t = 10 at 1e-12 on an H200: tiles of
# 2¹⁷, 1.7e5 members/s; 2¹⁸, 1.64e5/s; one tile of 10⁶, 4.3e4/s).
ACCELERATOR_TILE = 2**17


class _Carry(NamedTuple):
    t: jax.Array  # (B,)
    t_low: jax.Array  # (B,): t + t_low is the time in double-length arithmetic
    y: jax.Array  # (n, B)
    y_low: jax.Array  # (n, B): y + y_low, compensated summation
    ys: jax.Array  # (S, n, B)
    index: jax.Array  # (B,): the next save time to fill (inner-loop saving)
    num_steps: jax.Array  # (B,)
    result: RESULTS  # (B,)
    count: jax.Array  # loop iterations, for max_steps
    tape: jax.Array | None  # the coefficients' work buffer, reused by every step


def _where(pred: jax.Array, a: Any, b: Any) -> Any:
    """`RESULTS.where` for a predicate per member (that one takes a scalar)."""
    return jax.tree_util.tree_map(lambda x, y: jnp.where(pred, x, y), a, b)


def _leaf_axes(args: Any, args_axis: Any) -> tuple[bool, ...]:
    """Per leaf of args, whether it carries the batch on axis 0 (`args_axis`: None,
    0, or a pytree prefix of args made of None and 0, as `jax.vmap`'s in_axes)."""
    if args_axis is None or args_axis == 0:
        return (args_axis == 0,) * len(jax.tree_util.tree_leaves(args))
    flags = jax.tree_util.tree_map(
        lambda axis, sub: [axis == 0] * len(jax.tree_util.tree_leaves(sub)),
        args_axis,
        args,
        is_leaf=lambda x: x is None,
    )
    return tuple(jax.tree_util.tree_leaves(flags))


def _masked_saver(ts: jax.Array, direction: jax.Array) -> Callable:
    """Few save times (`ts`: (S, B), a column per member): every step evaluates
    its polynomial at all of them and keeps those inside each member's step."""

    def save(coeffs, t, t_low, t_new, ys, index, ok):
        taus = (ts - t) - t_low  # (S, B)
        inside = ok & (direction * (ts - t) > 0)
        inside &= direction * (ts - t_new) <= 0
        values = horner(coeffs, taus[:, None, :])  # (S, n, B)
        return jnp.where(inside[:, None, :], values, ys), index

    return save


def _loop_saver(ts: jax.Array, direction: jax.Array) -> Callable:
    """Many save times (`ts`: (S, B)): each member fills its next save while it
    lies inside its step, one save per member per inner iteration."""
    last = ts.shape[0] - 1

    def save(coeffs, t, t_low, t_new, ys, index, ok):
        members = jnp.arange(t.shape[0])

        def next_time(i):
            return ts[jnp.minimum(i, last), members]

        def wanted(i):
            return ok & (i <= last) & (direction * (next_time(i) - t_new) <= 0)

        def body(c):
            i, ys = c
            want = wanted(i)
            values = horner(coeffs, (next_time(i) - t) - t_low)
            row = jnp.where(want, i, last + 1)  # out of bounds: dropped
            ys = ys.at[row, :, members].set(values.T, mode="drop")
            return i + want, ys

        index, ys = jax.lax.while_loop(
            lambda c: jnp.any(wanted(c[0])), body, (index, ys)
        )
        return ys, index

    return save


def default_tile(platform: str, members: int) -> int:
    """Members per tile for a batch of `members` run on `platform` ("cpu",
    "gpu", "cuda", "rocm", "tpu"): `CPU_TILE` on a CPU; elsewhere the whole batch
    in as few equal tiles of at most `ACCELERATOR_TILE` as it takes."""
    if platform == "cpu":
        return CPU_TILE
    count = -(-members // ACCELERATOR_TILE)
    return max(1, -(-members // count))


def placement_platform(x: Any) -> str:
    """The platform `x` is computed on: its device's for a concrete array, else
    JAX's default device's (under `jit` a traced value has no device yet)."""
    if isinstance(x, jax.Array) and not isinstance(x, Tracer):
        return next(iter(x.devices())).platform
    device = jax.config.jax_default_device  # pyright: ignore[reportAttributeAccessIssue]
    if device is not None:
        return device if isinstance(device, str) else device.platform
    return jax.default_backend()


def taylor_integrate_batch(
    vector_field: Callable,
    y0s: Any,
    t0: Any,
    t1: Any,
    *,
    ts: Any = None,
    args: Any = None,
    args_axis: Any = None,
    rtol: Any = 1e-15,
    atol: Any = 1e-15,
    order: int | None = None,
    max_steps: int = 1_000_000,
    unroll: bool = False,
    scalar: bool = True,
    tile: int | None = None,
) -> TaylorSolution:
    """Integrate y' = vector_field(t, y, args) for every row of `y0s` (shape
    (B, n)) from t0 to t1 (scalars, or one per member, shape (B,)), by Taylor's
    method with one step size per member. Returns a `TaylorSolution` whose `ys`
    has shape (B, S, n) and whose `num_steps` and `result` have shape (B,).

    `ts` are the S save times, ordered from t0 towards t1: shape (S,) shared by
    the batch, or (B, S) a row per member; the default is t1 (shape (1,), or
    (B, 1) for a t1 per member); `TaylorSolution.ts` has the shape given.
    `args_axis` says which leaves of args carry the batch on their axis 0, like
    `jax.vmap`'s in_axes (None: shared by all members). `vector_field` sees one
    member, exactly as for `taylor_integrate`. `tile`: members per loop (None:
    `default_tile` for the platform the batch runs on).
    """
    p = resolve_order(rtol, atol, order)
    y0s = jnp.asarray(y0s)
    if y0s.ndim != 2 or not jnp.issubdtype(y0s.dtype, jnp.floating):
        raise TypeError(
            "lagjax.taylor_integrate_batch: y0s must be a float array of shape "
            f"(members, n), got {y0s.shape} {y0s.dtype}; for one trajectory use "
            "taylor_integrate"
        )
    members, dtype = y0s.shape[0], y0s.dtype
    tile = _checked_tile(tile, y0s)
    t0, t1, ts, member_ts = _member_times(t0, t1, ts, members, dtype)
    saves = member_ts.shape[0]
    leaf_flags = _leaf_axes(args, args_axis)
    leaves = [
        jnp.moveaxis(jnp.asarray(leaf), 0, -1) if batched else leaf
        for leaf, batched in zip(jax.tree_util.tree_leaves(args), leaf_flags)
    ]
    one_args = jax.tree_util.tree_map(
        lambda x, b: x[0] if b else x,
        args,
        jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(args), leaf_flags),
    )
    graph, _ = lower_vector_field(vector_field, t0[0], y0s[0], one_args, scalar=scalar)
    saver = _masked_saver if saves <= SMALL_SAVES else _loop_saver
    uses_tape = not unroll and supports(graph)

    def run_tile(t0, t1, ts, y0, leaves):
        direction = jnp.where(t1 >= t0, 1.0, -1.0).astype(dtype)
        save = saver(ts, direction)

        def coefficients(c: _Carry) -> tuple[jax.Array, jax.Array | None]:
            """The step's coefficients, and the tape to carry (None without one)."""
            run = lambda **tape: graph_coefficients(
                graph, c.t, c.y, leaves, p, unroll=unroll, batched_leaves=leaf_flags,
                **tape,
            )  # fmt: skip
            return (run(), None) if c.tape is None else run(tape=c.tape)

        def body(c: _Carry) -> _Carry:
            coeffs, tape = coefficients(c)
            h = step_size(coeffs, rtol, atol)
            active = (c.t != t1) & (c.result == RESULTS.successful)
            remaining = direction * ((t1 - c.t) - c.t_low)
            last = h >= remaining
            tau = jnp.where(active, direction * jnp.where(last, remaining, h), 0.0)
            t_sum, t_err = two_sum(c.t, tau)
            t_high, t_low = two_sum(t_sum, c.t_low + t_err)
            t_new = jnp.where(last, t1, t_high)
            y_new, y_low = compensated_advance(coeffs, tau, c.y_low)
            finite = jnp.all(jnp.isfinite(y_new), axis=0)
            ok = active & finite
            ys, index = save(coeffs, c.t, c.t_low, t_new, c.ys, c.index, ok)
            return _Carry(
                t=jnp.where(ok, t_new, c.t),
                t_low=jnp.where(ok, jnp.where(last, 0.0, t_low), c.t_low),
                y=jnp.where(ok, y_new, c.y),
                y_low=jnp.where(ok, y_low, c.y_low),
                ys=ys,
                index=index,
                num_steps=c.num_steps + ok,
                result=_where(active & ~finite, RESULTS.non_finite, c.result),
                count=c.count + 1,
                tape=tape,
            )

        def cond(c: _Carry) -> jax.Array:
            running = (c.t != t1) & (c.result == RESULTS.successful)
            return jnp.any(running) & (c.count < max_steps)

        at_start = direction * (ts - t0) <= 0  # (S, B)
        width = t0.shape[0]
        init = _Carry(
            t=t0,
            t_low=jnp.zeros_like(t0),
            y=y0,
            y_low=jnp.zeros_like(y0),
            ys=jnp.where(at_start[:, None, :], y0, jnp.nan),
            index=jnp.sum(at_start, axis=0),
            num_steps=jnp.zeros(width, int),
            result=_where(
                jnp.ones(width, bool), RESULTS.successful, RESULTS.successful
            ),
            count=jnp.array(0),
            # Carried, not made afresh per step: a new tape is zeroed each time (`tape`).
            tape=jnp.empty(tape_shape(graph, p, (width,)), dtype)
            if uses_tape
            else None,
        )
        final = jax.lax.while_loop(cond, body, init)
        result = _where(
            (final.t != t1) & (final.result == RESULTS.successful),
            RESULTS.max_steps_reached,
            final.result,
        )
        return final.ys, final.num_steps, result

    ys, num_steps, result = _tiled(
        run_tile, (t0, t1, member_ts, y0s.T, leaves), leaf_flags, tile
    )
    return TaylorSolution(
        ts=ts, ys=jnp.moveaxis(ys, -1, 0), num_steps=num_steps, result=result, order=p
    )


def _checked_tile(tile: int | None, y0s: jax.Array) -> int:
    """The user's tile, or the platform's default for this batch."""
    if tile is None:
        return default_tile(placement_platform(y0s), y0s.shape[0])
    if not isinstance(tile, int) or tile < 1:
        raise ValueError(
            f"lagjax.taylor_integrate_batch: tile must be a positive int, got {tile!r}"
        )
    return tile


def _member_times(t0: Any, t1: Any, ts: Any, members: int, dtype: Any) -> tuple:
    """(t0, t1) one per member, shape (B,); `ts` as given, (S,) or (B, S) (t1
    by default); and the save times a column per member, shape (S, B)."""
    if ts is None:
        ts = jnp.asarray(t1, dtype)[..., None]
    ts = jnp.atleast_1d(jnp.asarray(ts, dtype))
    if not (ts.ndim == 1 or (ts.ndim == 2 and ts.shape[0] == members)):
        raise TypeError(
            "lagjax.taylor_integrate_batch: ts must have shape (S,) (shared by the "
            f"batch) or ({members}, S) (a row per member), got shape {ts.shape}"
        )
    t0 = jnp.broadcast_to(jnp.asarray(t0, dtype), (members,))
    t1 = jnp.broadcast_to(jnp.asarray(t1, dtype), (members,))
    columns = ts.T if ts.ndim == 2 else ts[:, None]
    return t0, t1, ts, jnp.broadcast_to(columns, (ts.shape[-1], members))


def _tiled(run: Callable, inputs: tuple, leaf_flags: tuple, tile: int) -> Any:
    """`run(t0, t1, ts, y0, leaves)` on tiles of `tile` members in turn (the
    batch axis last everywhere): a member waits only for its tile's slowest, and
    a tile's values stay in cache. The batch is padded with copies of its last
    member to a whole number of tiles."""
    t0, t1, ts, y0, leaves = inputs
    members = t0.shape[0]
    if members <= tile:
        return run(t0, t1, ts, y0, leaves)
    count = -(-members // tile)
    pad = count * tile - members

    def split(x):  # (..., B) -> (tiles, ..., tile)
        x = jnp.concatenate([x, jnp.repeat(x[..., -1:], pad, axis=-1)], axis=-1)
        return jnp.moveaxis(x.reshape((*x.shape[:-1], count, tile)), -2, 0)

    def merge(x):  # (tiles, ..., tile) -> (..., B)
        x = jnp.moveaxis(x, 0, -2)
        return x.reshape((*x.shape[:-2], count * tile))[..., :members]

    batched = [split(x) for x, b in zip(leaves, leaf_flags) if b]

    def one(tile_inputs):
        t0, t1, ts, y0, picked = tile_inputs
        it = iter(picked)
        tile_leaves = [next(it) if b else x for x, b in zip(leaves, leaf_flags)]
        return run(t0, t1, ts, y0, tile_leaves)

    tiles = (split(t0), split(t1), split(ts), split(y0), batched)
    outputs = jax.lax.map(one, tiles)
    return jax.tree_util.tree_map(merge, outputs)
