"""Fixed-step integration as a plain `lax.scan` over a diffrax solver's `step`.

`diffrax.diffeqsolve` runs every solver inside a general adaptive loop: it carries
the previous and next times, the step-size controller's state, dense output and
save state, and selects accepted/rejected values every step. For a fixed step with
only the final state saved none of that is needed, and on CPU it is what separates
a diffrax run from a hand-written loop (measured in `benchmarks/solver_overhead.py`).
`simulate` therefore takes this path for `dt` given, default adjoint and no
progress meter, when only the final state is saved or the save times lie on the
step grid at a uniform spacing (`ts = linspace` over multiples of dt, every k-th
step): then two nested scans save without interpolation. The other savings —
`ts` off the grid, `SaveAt(steps=...)`, dense output — are scans too
(`scan_saving.py`, `off_grid_saves.py`, built on the step bodies and
`integrate_every_step` here). The solver and its `step` are the same diffrax
objects, so results match `diffeqsolve` with `ConstantStepSize` to round-off when
the span is a whole number of steps; otherwise the scans shorten the last step
where diffrax spreads the span over equal steps.

The scan bodies and what they carry are in `step_bodies.py`. Runs of
`BLOCKED_MIN_STEPS` or more (final state, or saved on the grid) take blocks of
untracked steps and locate a failure after the loop (`blocked_loop.py`): the same
results, and under `vmap` the step stays as lean as a hand-written one.
"""

from __future__ import annotations

import math
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from lagjax._integrate.blocked_loop import (
    BLOCKED_MIN_STEPS,
    BlockCarry,
    blocked_scan,
    fast_block,
    locate_failure,
    start_blocks,
)
from lagjax._integrate.scan_body import (
    TrackingCarry,
    fast_step_function,
    initial_tracking_carry,
    steps_per_trip,
    tracking_scan,
    tracking_step_function,
)


def fixed_step_count(t0: float, t1: float, dt: float) -> int:
    """Number of steps of size |dt| to cover [t0, t1], the last one shortened.

    A span that is an integer multiple of dt up to round-off is not given an extra
    sliver of a step.
    """
    ratio = abs((t1 - t0) / dt)
    nearest = round(ratio)
    if nearest >= 1 and abs(ratio - nearest) <= 1e-9 * ratio:
        return nearest
    return max(1, math.ceil(ratio))


# Compiled once per (terms, solver, times, state structure): terms and solvers are
# equinox Modules that compare by value, so repeated runs reuse the compilation.
@eqx.filter_jit
def integrate_fixed_steps(
    terms: Any,
    solver: diffrax.AbstractSolver,
    t0: float,
    t1: float,
    dt: float,
    y0: Any,
    args: Any,
    dtype: Any = float,
) -> tuple[Any, Any, Any]:
    """Take fixed steps from t0 to t1; return `(y1, result, steps_taken)`.

    `result` is the first unsuccessful diffrax `RESULTS` of any step (e.g. a failed
    implicit solve, or `nonfinite`), or `successful`. Grid times t0 + k·dt are
    formed in the default float precision and handed to the solver in the state's
    `dtype`. After a failure `y1` is the state of the last good step and
    `steps_taken` counts the steps up to it.
    """
    steps = fixed_step_count(t0, t1, dt)
    dt = math.copysign(abs(dt), t1 - t0)
    one_step = tracking_step_function(terms, solver, t0, dt, args, dtype, steps - 1, t1)
    initial = initial_tracking_carry(terms, solver, t0, dt, y0, args, dtype)
    if steps < BLOCKED_MIN_STEPS:
        final, _ = tracking_scan(one_step, initial, steps, solver)
    else:
        fast_step = fast_step_function(
            terms, solver, t0, dt, args, dtype, steps - 1, t1
        )
        final = blocked_scan(fast_step, one_step, initial, steps, solver)
    return final.last_good, final.result, final.taken


def uniform_grid_saves(
    t0: float, dt: float, ts: np.ndarray
) -> tuple[int, int, int] | None:
    """`(lead, every, saves)` when the save times are t0 + (lead + j·every)·dt for
    j = 0 … saves − 1 (to 1e-9 of a step), else None.

    These are the runs a nested scan saves without interpolation: `lead` steps to
    the first save, then `every` steps between saves.
    """
    if ts.ndim != 1 or ts.size == 0 or not np.all(np.isfinite(ts)):
        return None
    positions = (ts - t0) / dt
    indices = np.round(positions)
    if np.any(np.abs(positions - indices) > 1e-9 * np.maximum(1.0, np.abs(indices))):
        return None
    if indices[0] < 0:
        return None
    gaps = np.diff(indices)
    if gaps.size and (gaps[0] < 1 or np.any(gaps != gaps[0])):
        return None
    every = int(gaps[0]) if gaps.size else 1
    return int(indices[0]), every, int(ts.size)


@eqx.filter_jit
def integrate_fixed_steps_saving(
    terms: Any,
    solver: diffrax.AbstractSolver,
    t0: float,
    dt: float,
    grid: tuple[int, int, int],
    y0: Any,
    args: Any,
    dtype: Any = float,
) -> tuple[Any, Any, Any, Any]:
    """Fixed steps with the state saved on the step grid:
    `(ys, result, steps_taken, saved)`.

    `grid = (lead, every, saves)` from `uniform_grid_saves`: `lead` steps, a save,
    then `saves − 1` times `every` steps and a save. Two nested `lax.scan`s, so the
    saving costs one copy per save and nothing per step (a long run's intervals
    are its blocks, `blocked_loop.py`). `saved[j]` is False for the saves a
    failure kept from being reached; those hold the last good state.
    """
    lead, every, saves = grid
    initial = initial_tracking_carry(terms, solver, t0, dt, y0, args, dtype)
    one_step = tracking_step_function(terms, solver, t0, dt, args, dtype)
    if lead + every * (saves - 1) < BLOCKED_MIN_STEPS:
        return _saving_tracked(one_step, initial, grid, solver)
    fast_step = fast_step_function(terms, solver, t0, dt, args, dtype)
    return _saving_blocked(fast_step, one_step, initial, grid, solver)


def _saved_states(first, later):
    """Saves from the one before the loop and those the loop's scan emitted."""
    return jax.tree_util.tree_map(
        lambda a, b: jnp.concatenate([jnp.asarray(a)[None], b]), first, later
    )


def _holding(reached: jax.Array, ys: Any, held: Any) -> Any:
    """`ys` (stacked along the first axis) where `reached`, else the state `held`."""
    return jax.tree_util.tree_map(
        lambda y, last: jnp.where(
            reached.reshape(reached.shape + (1,) * (y.ndim - 1)), y, last
        ),
        ys,
        held,
    )


def _saving_tracked(one_step, carry: TrackingCarry, grid, solver):
    lead, every, saves = grid
    if lead:
        carry, _ = tracking_scan(one_step, carry, lead, solver)

    def save(carry: TrackingCarry):
        return carry.last_good, carry.result == diffrax.RESULTS.successful

    def interval(carry, _):
        carry, _ = tracking_scan(one_step, carry, every, solver)
        return carry, save(carry)

    first = save(carry)
    carry, later = jax.lax.scan(interval, carry, None, length=saves - 1)
    ys, saved = _saved_states(first, later)
    return ys, carry.result, carry.taken, saved


def _saving_blocked(fast_step, one_step, initial: TrackingCarry, grid, solver):
    """The saving loop in blocks (`blocked_loop.py`): the intervals between saves
    are the blocks. A save at or after a failure holds the last good state, which
    is known only once the failure is located after the loop."""
    lead, every, saves = grid
    carry = start_blocks(initial)
    if lead:
        carry = fast_block(fast_step, carry, lead, unroll=1)

    def save(carry: BlockCarry):
        return carry.steps.last_good, carry.steps.result == diffrax.RESULTS.successful

    def interval(carry, _):
        carry = fast_block(fast_step, carry, every, steps_per_trip(solver))
        return carry, save(carry)

    first = save(carry)
    carry, later = jax.lax.scan(interval, carry, None, length=saves - 1)
    final = locate_failure(one_step, carry, max(lead, every))
    ys, saved = _saved_states(first, later)
    return _holding(saved, ys, final.last_good), final.result, final.taken, saved


@eqx.filter_jit
def integrate_every_step(
    terms: Any,
    solver: diffrax.AbstractSolver,
    t0: float,
    t1: float,
    dt: float,
    y0: Any,
    args: Any,
    dtype: Any = float,
    states: bool = True,
    dense: bool = False,
) -> tuple[Any, Any, Any, Any, Any]:
    """Fixed steps from t0 to t1 keeping every step:
    `(y1, ys, dense_infos, result, steps_taken)`.

    One `lax.scan` whose outputs are, per step, the new state (`states`: for
    `SaveAt(steps=...)`) and the solver's dense information (`dense`: the
    `diffrax.DenseInterpolation` of the run). Entries after a failure repeat the
    last good state; `steps_taken` says how many are results.
    """
    steps = fixed_step_count(t0, t1, dt)
    dt = math.copysign(abs(dt), t1 - t0)

    def emit(y, dense_info):
        return (y if states else None), (dense_info if dense else None)

    one_step = tracking_step_function(
        terms, solver, t0, dt, args, dtype, steps - 1, t1, emit
    )
    initial = initial_tracking_carry(terms, solver, t0, dt, y0, args, dtype)
    final, kept = tracking_scan(one_step, initial, steps, solver)
    ys, infos = kept  # pyright: ignore[reportGeneralTypeIssues]
    if states:
        # Emitting the running state keeps the selects of the last good state
        # off the stacked output; the entries from the failure on are masked here.
        ys = _holding(jnp.arange(1, steps + 1) <= final.taken, ys, final.last_good)
    return final.last_good, ys, infos, final.result, final.taken
