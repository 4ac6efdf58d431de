"""The bodies of the fixed-step loop: one step k → k + 1 of a diffrax solver as a
`lax.scan` body, and what the loop carries.

Three bodies, for three needs. `tracking_step_function` takes every step and keeps
the last good state beside the running one (failures are detected cheaply, acted
on after the loop), so nothing on the path from one step to the next splits XLA's
fused step. `fast_step_function` keeps nothing but the state, the solver's state,
its first reported failure and the step index: the blocked loop (`blocked_loop.py`)
tests a whole block of its steps at once and searches a failed block again with
the tracking body. `step_function` refuses to take a failed step or one past a
bound, for the off-grid saves whose inner scans have a fixed length.
Times are formed from the step index (`step_times`), never accumulated.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import diffrax
import jax
import jax.numpy as jnp

from lagjax.solvers.splitting_engine import AbstractSplittingSolver


def tree_select(flag: Any, new: Any, old: Any) -> Any:
    """`new` where `flag`, else `old`, leaf by leaf (`flag` a scalar per member)."""
    return jax.tree_util.tree_map(lambda a, b: jnp.where(flag, a, b), new, old)


def first_failure(result: Any, new_result: Any) -> Any:
    """The run's result after one more outcome: the first failure is kept."""
    return diffrax.RESULTS.where(
        result == diffrax.RESULTS.successful, new_result, result
    )


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
    # A step that does not count cannot fail the run.
    step_result = diffrax.RESULTS.where(counts, step_result, result)
    return y_next, state_next, dense_info, first_failure(result, step_result)


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
        y, solver_state = tree_select(stay, (y, solver_state), (y_next, state_next))
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

    `emit(y, dense_info)`, when given, is what the scan outputs per step from the
    step's new state (the state for `SaveAt(steps=True)`, the dense information
    for dense output); entries from a failed step on are the caller's to mask,
    with `taken`.
    """

    def one_step(carry: TrackingCarry, _):
        times = step_times(t0, dt, carry.k, dtype, last_step, t1)
        y_next, state_next, dense_info, result = _attempt_step(
            terms, solver, times, carry.y, carry.solver_state, carry.result, args,
            jnp.asarray(True),
        )  # fmt: skip
        good = result == diffrax.RESULTS.successful
        last_good = tree_select(good, y_next, carry.last_good)
        taken = jnp.where(good, carry.k + 1, carry.taken)
        new = TrackingCarry(y_next, state_next, result, carry.k + 1, last_good, taken)
        return new, None if emit is None else emit(y_next, dense_info)

    return one_step


def fast_step_function(terms, solver, t0, dt, args, dtype, last_step=None, t1=None):
    """The scan body of one fixed step k → k + 1 over a `TrackingCarry` that
    updates only `y`, `solver_state`, `result` and `k`.

    No finiteness test and no last good state: under `vmap` the step is
    throughput-bound and those cost in proportion to it (compensated
    Störmer–Verlet on Kepler ×64: 1.45× a hand-written scan with them per step,
    1.07× without). `result` keeps the solver's first reported failure (a constant
    for the explicit splittings, which XLA folds away). The blocked loop tests the
    state once per block and leaves `last_good` and `taken` to its block ends.
    """

    def one_step(carry: TrackingCarry, _):
        start, end = step_times(t0, dt, carry.k, dtype, last_step, t1)
        y_next, _, _, state_next, step_result = solver.step(
            terms, start, end, carry.y, args, carry.solver_state, False
        )
        result = first_failure(carry.result, step_result)
        new = carry._replace(
            y=y_next, solver_state=state_next, result=result, k=carry.k + 1
        )
        return new, None

    return one_step


def tracking_scan(
    one_step, carry: TrackingCarry, length: int, solver: diffrax.AbstractSolver
):
    """`lax.scan` of a `tracking_step_function` body, `steps_per_trip(solver)`
    steps per loop iteration (the arithmetic of each step is unchanged)."""
    unroll = steps_per_trip(solver)
    return jax.lax.scan(one_step, carry, None, length=length, unroll=unroll)


# Splittings with up to this many force evaluations per step run two steps per
# loop iteration, and those with one (Störmer–Verlet) four (see `steps_per_trip`).
UNROLLED_SPLITTING_STAGES = 6


def steps_per_trip(solver: diffrax.AbstractSolver) -> int:
    """How many steps one iteration of the fixed-step loop takes: 4 for a
    splitting with one force evaluation per step, 2 for the other short explicit
    splittings, 1 otherwise.

    Unrolled by two, XLA fuses across the step boundary and the loop's own cost is
    paid half as often: Kepler with compensated Störmer–Verlet 25 → 20 ns per step,
    Yoshida4 59 → 53 (`benchmarks/solver_overhead.py`). Störmer–Verlet's step is
    so short that four per trip gain again: one trajectory of 2·10⁵ steps
    1.33–1.39× → 1.25–1.27× the plain hand-written scan, with 1001 saves over
    4·10⁴ steps 1.48–1.49× → 1.42–1.43× (process CPU time, alternated runs;
    ×64 unchanged within the noise; eight per trip measured 1.38–1.40× with
    saves, not worth the larger body). For longer steps (an
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
        if stages == 1:
            return 4
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
