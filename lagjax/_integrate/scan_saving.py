"""Every way a fixed-step run saves, as scans: what `SaveAt` asks, and its output.

`simulate` runs a fixed-step run as `lax.scan`s over the solver's step
(`fixed_step.py`) instead of `diffrax.diffeqsolve`'s general loop, which carries
times, controller state and save state through every step and costs a multiple
of a hand-written loop (`benchmarks/dense_output.py`). This module covers the
saving requests beyond the final state and a uniform subgrid of the steps:

| request | how |
|---|---|
| `ts=` anywhere in [t0, t1] | nested scans, the continuous extension over each save's step (`off_grid_saves`) |
| `SaveAt(steps=k)` (every k-th step) | one scan keeping each step's state |
| `dense=True` / `SaveAt(dense=True)` | one scan keeping each step's dense information: a `diffrax.DenseInterpolation`, as `diffeqsolve` builds it |
| `SaveAt(t0=True)`, `SaveAt(t1=True)` | y0 in front, the final state at the end |

The output has `diffeqsolve`'s layout: `t0`, then `ts` or the steps, then `t1`;
`SaveAt(steps=k)` has `max_steps // k` slots, those no step filled at t = inf
with inf states (so has every save a failure kept from being reached). The
continuous extension is the one `diffeqsolve` would use — the solver's own, or
`lagjax.solvers.hermite`'s for solvers whose own is linear — so results agree with it to
round-off on a span that is a whole number of steps (the scan shortens a last
step where diffrax spreads the span over equal steps). One exception: backward
runs (t1 < t0) of a Hermite-extended solver, which diffeqsolve's time reversal
interpolates wrongly (1e-3 off on the oscillator at h = 0.01); the scan follows
the solution (`tests/test_scan_saving.py`). Requests outside this table
(`SaveAt(fn=...)`, `subs`, `SaveAt(ts=...)`, traced `ts`, save times bunched far
apart) stay on `diffeqsolve`.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from lagjax._integrate.fixed_step_loop import (
    fixed_step_count,
    integrate_every_step,
    integrate_fixed_steps,
)
from lagjax._integrate.off_grid_saves import integrate_off_grid, off_grid_schedule
from lagjax._integrate.step_control import diffrax_step_bound
from lagjax._integrate.time_grid import grid_step
from lagjax.solvers.hermite import with_dense_output

# diffrax's default `SubSaveAt.fn` (save the state itself), without its private module.
_SAVE_STATE = diffrax.SubSaveAt(t1=True).fn


class ScanSaving(NamedTuple):
    """What a fixed-step run saves, and the grid it steps on."""

    step: float  # the signed step of the exact grid (`step_grid`)
    t0: bool
    ts: np.ndarray | None
    every: int  # SaveAt(steps=every); 0 for none
    t1: bool
    dense: bool
    limit: int  # max_steps: SaveAt(steps=k) keeps max_steps // k slots
    schedule: tuple[np.ndarray, int] | None  # off_grid_schedule of ts


def scan_saving(
    t0: float,
    t1: float,
    dt: float,
    ts: Any,
    saveat: diffrax.SaveAt | None,
    dense: bool,
    max_steps: int | None,
    dtype: Any,
) -> ScanSaving | None:
    """The saving a scan does for this fixed-step run, or None (module docstring)."""
    if saveat is None:
        sub = diffrax.SubSaveAt(ts=ts) if ts is not None else diffrax.SubSaveAt(t1=True)
    else:
        sub = saveat.subs
        extras = saveat.solver_state or saveat.controller_state or saveat.made_jump
        if (
            extras
            or not isinstance(sub, diffrax.SubSaveAt)
            or sub.fn is not _SAVE_STATE
        ):
            return None
        dense = dense or saveat.dense
    step = math.copysign(abs(grid_step(t0, t1, dt, dtype)), t1 - t0)
    count = fixed_step_count(t0, t1, step)
    if max_steps is not None and max_steps < count:
        return None  # diffeqsolve reports max_steps_reached
    times, schedule = None, None
    if sub.ts is not None:
        if saveat is not None:
            # SaveAt's ts reach simulate's compiled call traced, where the scan
            # cannot lay out its loops; `ts=` reaches it static.
            return None
        try:
            # `ts` itself: SubSaveAt makes it a JAX array, traced under a jit.
            times = np.asarray(ts, dtype=float)
        except jax.errors.TracerArrayConversionError:
            return None
        if not dense:
            schedule = off_grid_schedule(t0, t1, step, times)
            if schedule is None:
                return None
    # diffeqsolve's default for fixed steps (`diffeqsolve_run`).
    limit = max_steps or diffrax_step_bound(t0, t1, dt)
    assert limit is not None  # concrete times
    return ScanSaving(step, sub.t0, times, sub.steps, sub.t1, dense, limit, schedule)


def integrate_saving(terms, solver, state0, args, plan: ScanSaving, t0, t1, dtype,
                     off_grid=integrate_off_grid,
                     every_step=integrate_every_step):  # fmt: skip
    """Run the scans of `plan`: `(saved_ts, ys, result, steps_taken, interpolation)`;
    `off_grid` saves `ts` off the step grid and `every_step` keeps every step
    (`ReversibleAdjoint.off_grid_saves` and `.every_step` under that adjoint)."""
    step, direction = plan.step, 1 if t1 > t0 else -1
    parts = []  # (times, states, saved) in diffeqsolve's order
    if plan.t0:
        parts.append(_one(jnp.asarray(t0, dtype), state0, True))
    interpolation = None
    if plan.dense or plan.every:
        dense_solver = with_dense_output(solver, terms) if plan.dense else solver
        y1, ys, infos, result, taken = every_step(
            terms, dense_solver, t0, t1, step, state0, args, dtype,
            states=bool(plan.every), dense=plan.dense,
        )  # fmt: skip
        grid = _grid_times(t0, t1, step, dtype)
        reached = grid[taken]
        if plan.dense:
            interpolation = diffrax.DenseInterpolation(
                ts=grid * direction,
                ts_size=taken + 1,
                infos=infos,
                interpolation_cls=dense_solver.interpolation_cls,
                direction=direction,
                t0_if_trivial=jnp.asarray(t0 * direction, dtype),
                y0_if_trivial=state0,
            )
        if plan.ts is not None:
            assert interpolation is not None
            times = jnp.asarray(plan.ts, dtype)
            values = jax.vmap(interpolation.evaluate)(times)
            parts.append((times, values, direction * times <= direction * reached))
        if plan.every:
            parts.append(_every_kth(plan, grid, ys, taken, reached, y1))
        elif plan.t1:
            parts.append(_one(reached, y1, True))
    elif plan.ts is not None:
        assert plan.schedule is not None
        times = jnp.asarray(plan.ts, dtype)
        values, result, taken, saved = off_grid(
            terms, solver, with_dense_output(solver, terms), t0, t1, step,
            plan.schedule[0], plan.schedule[1], times, state0, args, dtype,
        )  # fmt: skip
        parts.append((times, values, saved))
        if plan.t1:
            final = _grid_times(t0, t1, step, dtype)[taken]
            parts.append(_one(final, _last(values, saved, state0), True))
    else:
        y1, result, taken = integrate_fixed_steps(
            terms, solver, t0, t1, step, state0, args, dtype
        )
        parts.append(_one(_grid_times(t0, t1, step, dtype)[taken], y1, True))
    saved_ts, ys = _concatenated(parts)
    return saved_ts, ys, result, taken, interpolation


def _grid_times(t0, t1, step, dtype) -> jax.Array:
    """t0 + k·step for k = 0 … n in `dtype`, the last one t1 (`step_times`)."""
    count = fixed_step_count(t0, t1, step)
    times = (t0 + jnp.arange(count + 1) * step).astype(dtype)
    return times.at[count].set(jnp.asarray(t1, dtype))


def _one(t, y, saved):
    leading = jax.tree_util.tree_map(lambda x: jnp.asarray(x)[None], y)
    return jnp.asarray(t)[None], leading, jnp.asarray(saved)[None]


def _last(values, saved, state0):
    """The last saved state (the final one of an off-grid run that saved t1)."""
    index = jnp.maximum(jnp.sum(saved) - 1, 0)
    return jax.tree_util.tree_map(lambda v: v[index], values)


def _every_kth(plan, grid, ys, taken, reached, y1):
    """The `SaveAt(steps=k)` part: `max_steps // k` slots (one more when t1 is
    asked and k does not divide max_steps), the final state at the slot after
    the last step saved when t1 is asked and the steps did not save it
    (diffrax's layout)."""
    every = plan.every
    kept = jax.tree_util.tree_map(lambda y: y[every - 1 :: every], ys)
    times = grid[every::every]
    size = plan.limit // every + (1 if plan.t1 and plan.limit % every else 0)
    filled = taken // every
    index = jnp.arange(size)
    final_here = (index == filled) & (plan.t1 & (taken % every != 0))
    saved = (index < filled) | final_here

    def slots(rows, last):
        pad = jnp.zeros((size - rows.shape[0], *rows.shape[1:]), rows.dtype)
        full = jnp.concatenate([rows, pad])[:size]
        mask = final_here.reshape((-1,) + (1,) * (full.ndim - 1))
        return jnp.where(mask, last, full)

    states = jax.tree_util.tree_map(slots, kept, y1)
    return slots(times, reached), states, saved


def _concatenated(parts):
    """The parts end to end; unsaved entries t = inf with inf states."""
    times = jnp.concatenate([p[0] for p in parts])
    saved = jnp.concatenate([p[2] for p in parts])
    states = jax.tree_util.tree_map(
        lambda *leaves: jnp.concatenate(leaves), *[p[1] for p in parts]
    )
    states = jax.tree_util.tree_map(
        lambda x: jnp.where(saved.reshape((-1,) + (1,) * (x.ndim - 1)), x, jnp.inf),
        states,
    )
    return jnp.where(saved, times, jnp.inf), states
