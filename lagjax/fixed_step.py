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

Two step bodies: `tracking_step_function` takes every step and keeps the last good
state beside the running one (failures are detected cheaply, acted on after the
loop), so nothing on the path from one step to the next splits XLA's fused step;
`step_function` refuses to take a failed step or one past a bound, for the
off-grid saves whose inner scans have a fixed length.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .solvers.splitting import AbstractSplittingSolver


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


def _attempt_step(terms, solver, times, y, solver_state, result, args, counts):
    """One step from `y` and the run's result after it: `(y_next, state_next,
    dense_info, result)`.

    A failure — the solver's own `RESULTS`, or a non-finite state
    (`RESULTS.nonfinite`: one sum of the state, inside the fused step) — is
    recorded in `result` when `counts` and the run had not failed before; the
    first failure is the one kept.
    """
    start, end = times
    y_next, _, dense_info, state_next, step_result = solver.step(
        terms, start, end, y, args, solver_state, False
    )
    step_result = diffrax.RESULTS.where(
        all_finite(y_next),
        step_result,
        diffrax.RESULTS.nonfinite,  # pyright: ignore[reportArgumentType]
    )
    counts = counts & (result == diffrax.RESULTS.successful)
    return (
        y_next,
        state_next,
        dense_info,
        diffrax.RESULTS.where(counts, step_result, result),
    )


def step_function(terms, solver, t0, dt, args, dtype, last_step, t1, until):
    """The scan body of one fixed step k → k + 1, carrying (y, state, result, k),
    that does not take a failed step or any step from index `until` on.

    A step not taken leaves the state, the solver's state (e.g. a compensated
    sum's error term) and the step index as they were, so a scan of fixed length
    can take a varying number of steps (`off_grid_saves`), and a failed run stops
    at its last good step. Those selects sit on the path from one step to the
    next and split XLA's fused step: the runs that need neither use
    `tracking_step_function`. Times are those of `step_times`.
    """

    def one_step(carry, _):
        y, solver_state, result, k = carry
        times = step_times(t0, dt, k, dtype, last_step, t1)
        counts = k < until
        y_next, state_next, _, result = _attempt_step(
            terms, solver, times, y, solver_state, result, args, counts
        )
        stay = (result != diffrax.RESULTS.successful) | ~counts
        y, solver_state = jax.tree_util.tree_map(
            lambda new, old: jnp.where(stay, old, new),
            (y_next, state_next),
            (y, solver_state),
        )
        return (y, solver_state, result, jnp.where(stay, k, k + 1)), None

    return one_step


class TrackingCarry(NamedTuple):
    """What a scan of `tracking_step_function` carries from step to step."""

    y: Any  # the state the next step starts from (poisoned after a failure)
    solver_state: Any
    result: Any  # the first failure, or successful
    k: Any  # steps computed
    last_good: Any  # the state after the last step that did not fail
    taken: Any  # steps up to and including that one


def tracking_step_function(
    terms, solver, t0, dt, args, dtype, last_step=None, t1=None, emit=None
):
    """The scan body of one fixed step k → k + 1 over a `TrackingCarry`.

    Detect cheaply, diagnose late: every step is taken, a failure only recorded
    in `result`, and the state runs on (poisoned) after it; beside it the carry
    keeps the last good state and the number of steps that reached it. Those
    selects are off the path from one step to the next, so XLA keeps the step
    one fused kernel: Kepler with compensated Störmer–Verlet 30 → 25 ns per step
    (`benchmarks/solver_overhead.py`), with bit-identical results. So a failed
    run still returns what it computed up to the failure and where it stopped.

    Times are formed from the step index (t0 + k·dt), not accumulated, so every
    step has the same h to the last bit on an exact grid (`step_grid`). The step
    index is carried, not scanned over: with `xs = arange(steps)` XLA on CPU
    launched the fused pieces of a larger step body one by one (measured 10× on
    Kepler with Yoshida4, 2× on a rigid body; bit-identical results). When
    `last_step` is given, that step ends exactly at `t1` (a shortened last step).

    `emit(y, dense_info)`, when given, is what the scan outputs per step (the
    last good state for `SaveAt(steps=True)`, the dense information for dense
    output).
    """

    def one_step(carry: TrackingCarry, _):
        times = step_times(t0, dt, carry.k, dtype, last_step, t1)
        y_next, state_next, dense_info, result = _attempt_step(
            terms, solver, times, carry.y, carry.solver_state, carry.result, args,
            jnp.asarray(True),
        )  # fmt: skip
        good = result == diffrax.RESULTS.successful
        last_good = jax.tree_util.tree_map(
            lambda new, old: jnp.where(good, new, old), y_next, carry.last_good
        )
        taken = jnp.where(good, carry.k + 1, carry.taken)
        new = TrackingCarry(y_next, state_next, result, carry.k + 1, last_good, taken)
        return new, None if emit is None else emit(last_good, dense_info)

    return one_step


def tracking_scan(
    one_step, carry: TrackingCarry, length: int, solver: diffrax.AbstractSolver
):
    """`lax.scan` of a `tracking_step_function` body, `steps_per_trip(solver)`
    steps per loop iteration (the arithmetic of each step is unchanged)."""
    unroll = steps_per_trip(solver)
    return jax.lax.scan(one_step, carry, None, length=length, unroll=unroll)


# Splittings with up to this many force evaluations per step run two steps per
# loop iteration (see `steps_per_trip`).
UNROLLED_SPLITTING_STAGES = 6


def steps_per_trip(solver: diffrax.AbstractSolver) -> int:
    """How many steps one iteration of the fixed-step loop takes: 2 for the short
    explicit splittings, 1 otherwise.

    Unrolled by two, XLA fuses across the step boundary and the loop's own cost is
    paid half as often: Kepler with compensated Störmer–Verlet 25 → 20 ns per step,
    Yoshida4 59 → 53 (`benchmarks/solver_overhead.py`). For longer steps (an
    eighth-order composition, an implicit stage solve, a Lie–Poisson step of
    nested scans) the loop's cost is a small part of the step and unrolling
    measured no gain, while it doubles the compiled loop body (compile time of the
    splitting, implicit and rigid-body test files +10 %).
    """
    # A wrapper (the Hermite extension, a projection) steps like what it wraps;
    # diffrax's wrappers also pass `isinstance` checks for it, hence the unwrapping.
    while isinstance(solver, diffrax.AbstractWrappedSolver):
        solver = solver.solver
    if isinstance(solver, AbstractSplittingSolver):
        stages = len(solver.drift_coefficients)
        return 2 if stages <= UNROLLED_SPLITTING_STAGES else 1
    return 1


def step_times(t0, dt, k, dtype, last_step=None, t1=None) -> tuple[Any, Any]:
    """(t_k, t_{k+1}) of step k in `dtype`: t0 + k·dt, the last step ending at t1."""
    start = (t0 + k * dt).astype(dtype)
    end = t0 + (k + 1) * dt
    if last_step is not None:
        end = jnp.where(k == last_step, t1, end)  # pyright: ignore[reportArgumentType]
    return start, end.astype(dtype)


def all_finite(state: Any) -> jax.Array:
    """Whether every entry of `state` is finite: one sum (inf and NaN propagate)."""
    total = sum(jnp.sum(leaf) for leaf in jax.tree_util.tree_leaves(state))
    return jnp.isfinite(total)


def initial_carry(terms, solver, t0, dt, y0, args, dtype):
    state = solver.init(
        terms, jnp.asarray(t0, dtype), jnp.asarray(t0 + dt, dtype), y0, args
    )
    return (y0, state, diffrax.RESULTS.successful, jnp.asarray(0))


def initial_tracking_carry(terms, solver, t0, dt, y0, args, dtype) -> TrackingCarry:
    y0, state, result, k = initial_carry(terms, solver, t0, dt, y0, args, dtype)
    return TrackingCarry(y0, state, result, k, y0, k)


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
    final, _ = tracking_scan(one_step, initial, steps, solver)
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
    saving costs one copy per save and nothing per step. `saved[j]` is False for
    the saves a failure (see `tracking_step_function`) kept from being reached.
    """
    lead, every, saves = grid
    one_step = tracking_step_function(terms, solver, t0, dt, args, dtype)
    carry = initial_tracking_carry(terms, solver, t0, dt, y0, args, dtype)
    if lead:
        carry, _ = tracking_scan(one_step, carry, lead, solver)

    def save(carry: TrackingCarry):
        return carry.last_good, carry.result == diffrax.RESULTS.successful

    def interval(carry, _):
        carry, _ = tracking_scan(one_step, carry, every, solver)
        return carry, save(carry)

    first = save(carry)
    carry, later = jax.lax.scan(interval, carry, None, length=saves - 1)
    ys, saved = jax.tree_util.tree_map(
        lambda a, b: jnp.concatenate([jnp.asarray(a)[None], b]), first, later
    )
    return ys, carry.result, carry.taken, saved


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
    return final.last_good, ys, infos, final.result, final.taken
