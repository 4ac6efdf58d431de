r"""`simulate` with `lj.TimeTransformed`: equal fictitious steps, states at physical times.

The splitting method steps the extended state $Y = ((p, p_t), (q, t))$ by equal
fictitious steps $ds$ (`lagjax.solvers.time_transformed`); the physical time $t$ is
part of the state. `GraggBulirschStoer` (`lagjax.solvers.extrapolation`) steps it
by fictitious steps its error estimate chooses, starting from $ds$: a refused step
leaves $Y$ where it was and is retried shorter. A save time $\tau$ is met without
interpolation:

1. the loop records, for each save time, the extended state $Y_n$ at the start of
   the step that carries $t$ across it ($t_n \le \tau \le t_{n+1}$) and that
   step's $ds$: one slot per save time, written once, O(1) work per step;
2. after the loop, a partial step $\Phi_{\sigma\,ds}(Y_n)$ from each recorded
   state, with $\sigma \in [0, 1]$ solved by the secant method on
   $t(\Phi_{\sigma ds}(Y_n)) = \tau$ ($t(\sigma)$ is nearly linear, so a few
   iterations reach round-off). The saved state is a step of the method itself,
   so saves keep its order; the main sequence of steps is never altered by saving.

Two loops run the same step:

- `max_steps=None`: for each save time in turn a `lax.while_loop` until $t$ passes
  it (the exact number of steps; `jit`, `vmap`, `jax.jvp`/`jacfwd`), the recorded
  states the output of a `lax.scan` over the save times, not a buffer in the
  loop's state (`_walk_to_saves`: under `vmap` that keeps the per-step work
  independent of the number of saves).
- `max_steps=N`: a `lax.scan` of N steps, frozen once the last save time is passed
  (reverse mode: `jax.grad` through the run). Too few steps leave the late saves
  unreached: an error, or with `throw=False` `traj.result` says
  `max_steps_reached` and those saves are NaN.

References: Mikkola & Tanikawa, Celest. Mech. 74, 287 (1999); Preto & Tremaine,
AJ 118, 2532 (1999); Hairer, Lubich & Wanner, *Geometric Numerical Integration*
(2006), §VIII.2.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from lagjax._core.precision import cast_floats, working_dtype
from lagjax._integrate.checks.inputs import MAX_FIXED_STEPS, check_simulate_inputs
from lagjax._integrate.time_transformed_double_double import double_double_steps
from lagjax._linalg.double_double import rounded_tree
from lagjax._linalg.double_double_arithmetic import DoubleDouble
from lagjax.solvers.time_transformed import (
    TimeTransformed,
    extended_state,
    start_weights,
)
from lagjax.trajectory import Trajectory

SECANT_ITERATIONS = 7


def run_time_transformed(
    system: Any, y0: Any, t0: Any, t1: Any, ds: Any, solver: TimeTransformed,
    ts: Any, args: Any, max_steps: int | None, throw: bool, **options: Any,
) -> Trajectory:  # fmt: skip
    """`simulate` for a `TimeTransformed` solver: the checks, the run, the verdict."""
    y0, t1 = check_fictitious_time_inputs(
        solver.name, "the fictitious step ds (dt/ds = w(−V))",
        system, y0, t0, t1, ds, ts, args, max_steps, options,
    )  # fmt: skip
    system, args = system.resolve(args)
    dtype = working_dtype(y0)
    system.check_start(y0, t0, args, dtype)
    try:  # the system's own answer: only a separable H has a drift and a kick
        _, _, integrated = system.integration(solver.splitting, y0, t0, args)
    except ValueError as error:
        raise ValueError(f"{solver.name} needs H = T(p) + V(q): {error}") from None
    y0, args = cast_floats(y0, dtype), cast_floats(args, dtype)
    weight0, mean_weight = start_weights(solver, integrated, y0, t0, args)
    if not isinstance(weight0, Tracer) and not (np.isfinite(weight0) and weight0 > 0):
        raise ValueError(
            f"{solver.name}: the weight w(−V) = dt/ds is {float(weight0)} at the "
            "start; it must be positive and finite (the logarithmic Hamiltonian "
            "needs V(q0) < 0, an attractive potential that vanishes at infinity)"
        )
    _check_step_count(solver, t0, t1, ds, weight0, mean_weight)
    save_ts = jnp.reshape(jnp.asarray(t1 if ts is None else ts, dtype=dtype), (-1,))
    trajectory = _compiled_run(
        integrated, y0, args, solver, jnp.asarray(t0, dtype), jnp.asarray(ds, dtype),
        save_ts, max_steps,
    )  # fmt: skip
    if throw:
        trajectory = eqx.error_if(
            trajectory,
            (trajectory.result != diffrax.RESULTS.successful)
            | ~(weight0 > 0)
            | ~jnp.isfinite(weight0),
            f"{solver.name} did not reach the last save time (raise max_steps), "
            "or the weight dt/ds was not positive at the start",
        )
    return trajectory


def check_fictitious_time_inputs(
    name: str, step_meaning: str, system: Any, y0: Any, t0: Any, t1: Any, ds: Any,
    ts: Any, args: Any, max_steps: int | None, options: dict[str, Any],
) -> tuple[Any, Any]:  # fmt: skip
    """The checks every run in fictitious time shares (`TimeTransformed`,
    `ChainRegularization`): no other saving options, a positive fictitious step
    `dt`, forward in time. Returns the checked y0 and t1 (the system's default
    span when None)."""
    given = [option for option, value in options.items() if value not in (None, False)]
    if given:
        raise ValueError(
            f"{name} does not support {', '.join(given)}: it saves at the "
            "physical times ts=..., stepping by the fictitious step dt"
        )
    if ds is None:
        raise ValueError(f"{name} needs dt, {step_meaning}")
    if not isinstance(ds, Tracer) and not float(ds) > 0:
        raise ValueError(f"the fictitious step ds (dt) must be positive; got {ds}")
    if t1 is None:
        t1 = system.default_span()[0]
    # ds is no time step (dt = w·ds): the times are checked as an adaptive run's.
    y0 = check_simulate_inputs(system, y0, t0, t1, None, None, ts, args, max_steps)
    if not isinstance(t1, Tracer) and not float(t1) > float(t0):
        raise ValueError(f"{name} integrates forward: t1 must exceed t0")
    return y0, t1


def check_no_tolerances_for(solver: TimeTransformed, given: dict[str, Any]) -> None:
    """Refuse `simulate`'s rtol/atol with a `TimeTransformed` solver: its steps are
    the fictitious step dt, and an extrapolating inner solver carries its own
    tolerances; taken here they would be ignored without a word."""
    names = [name for name, value in given.items() if value is not None]
    if names:
        raise ValueError(
            f"{solver.name} takes no {' or '.join(names)} from simulate: a splitting "
            "table steps by the fictitious step dt, and an extrapolating one has its "
            "own, e.g. lj.TimeTransformed(lj.GraggBulirschStoer(rtol=1e-13, "
            "atol=1e-13)). Or pass no solver: a tolerance run of a gravitating "
            "two-body scene picks a time-transformed method itself"
        )


def _check_step_count(solver: TimeTransformed, t0: Any, t1: Any, ds: Any,
                      weight0: Any, mean_weight: Any) -> None:  # fmt: skip
    """Refuse a fictitious step that would take ≥ 10⁹ steps (in days and AU,
    ds = 1e-6 is a step of a few days), at the faster of the start's pace
    dt = w(−V₀)·ds and a bound orbit's mean pace w(−2E)·ds: from the pericentre
    of Kepler's e = 0.9999 the start's pace alone is 10⁴ times too slow."""
    values = (t0, t1, ds, weight0, mean_weight)
    if any(isinstance(value, Tracer) for value in values):
        return
    pace = float(weight0)
    if np.isfinite(mean_weight) and float(mean_weight) > pace:
        pace = float(mean_weight)
    steps = (float(t1) - float(t0)) / (float(ds) * pace)
    if steps > MAX_FIXED_STEPS:
        raise ValueError(
            f"{solver.name}: ds = {float(ds):g} is a physical step of "
            f"{float(ds) * pace:g} (dt = w(−V)·ds), so "
            f"[{float(t0):g}, {float(t1):g}] would take about {steps:.3g} steps, "
            f"more than {MAX_FIXED_STEPS:.0e}: pass a larger dt (the fictitious step)"
        )


class _Carry(NamedTuple):
    """The loop's state: the extended state, the solver's, the fictitious step,
    the step and rejection counts, the index of the first save time not yet
    passed, and the recorded (start state, step) pairs (one slot per save time, a
    spare that takes the unused writes, and one left NaN for the saves never
    reached)."""

    y: Any
    solver_state: Any
    ds: jax.Array
    steps: jax.Array
    rejected: jax.Array
    next_save: jax.Array
    slots: Any


class _Walk(NamedTuple):
    """The `while_loop`'s state between two save times: the extended state, the
    solver's, the fictitious step, the step and rejection counts, and the start
    of the last step taken with its fictitious step."""

    y: Any
    solver_state: Any
    ds: jax.Array
    steps: jax.Array
    rejected: jax.Array
    start: Any


def _time(y: Any) -> jax.Array:
    """t of the extended state ((p, p_t), (q, t)) (its high part in double-double)."""
    t = y[1][1]
    return t.hi if isinstance(t, DoubleDouble) else t


def _stepper(terms: Any, splitting: Any, args: Any):
    """`advance(y, solver_state, ds) -> (y1, solver_state1, next ds, accepted)`: a
    splitting step (always taken, ds fixed) or an extrapolation step, which a
    refused step leaves where it was and retries shorter."""

    def advance(y, solver_state, ds):
        zero = jnp.zeros((), ds.dtype)
        y1, error, _, solver_state1, _ = splitting.step(
            terms, zero, ds, y, args, solver_state, False
        )
        if error is None:
            return y1, solver_state1, ds, True
        accepted, ds_next = splitting.adapt(ds, y, y1, error)
        y1, solver_state1 = jax.tree_util.tree_map(
            lambda new, old: jnp.where(accepted, new, old),
            (y1, solver_state1),
            (y, solver_state),
        )
        return y1, solver_state1, ds_next, accepted

    return advance


def _walk_to_saves(advance, y0, solver_state0, ds, save_ts):
    """`max_steps=None`: for each save time in turn, a `while_loop` of steps until
    t reaches it; the start of the step that carried t across it (and its ds) is
    the scan's output for that save (kept from the save before when no step was
    needed). The loops' states are small, so a `jax.vmap` of the run, which turns
    each loop into a select over its whole state at every step, selects no buffer
    of saves (with one slot per save in the loop, 1024 Kepler orbits with 101
    saves ran 9.6 s instead of 0.13 s with 2)."""

    def one_step(walk: _Walk) -> _Walk:
        y1, solver_state, ds_next, accepted = advance(
            walk.y, walk.solver_state, walk.ds
        )
        refused = 1 - jnp.asarray(accepted, jnp.int32)
        return _Walk(y1, solver_state, ds_next, walk.steps + 1,
                     walk.rejected + refused, (walk.y, walk.ds))  # fmt: skip

    def to_save(walk: _Walk, tau: jax.Array) -> tuple[_Walk, Any]:
        walk = lax.while_loop(lambda w: _time(w.y) < tau, one_step, walk)
        return walk, walk.start

    counts = jnp.zeros((), jnp.int32)
    start = _Walk(y0, solver_state0, ds, counts, counts, (y0, ds))
    end, (starts, steps) = lax.scan(to_save, start, save_ts)
    return starts, steps, end.steps, end.rejected, _time(end.y) >= save_ts[-1]


def _fixed_steps_to_saves(advance, y0, solver_state0, ds, save_ts, t0, max_steps):
    """`max_steps=N`: a `lax.scan` of N steps (reverse mode runs through it),
    frozen once the last save time is passed; each save time's slot records the
    start of the step that carries t across it."""
    saves = save_ts.shape[0]

    def step(carry: _Carry, _: Any) -> tuple[_Carry, None]:
        y1, solver_state, ds_next, accepted = advance(
            carry.y, carry.solver_state, carry.ds
        )
        # compare_all: one fused comparison; the default method is a while loop
        # of log2(saves) trips inside every step.
        passed = jnp.searchsorted(
            save_ts, _time(y1), side="right", method="compare_all"
        ).astype(jnp.int32)
        # The start of a step that crosses save times goes to the first one's slot;
        # a refused step records nothing (at t0 it would pass a save time at t0).
        passed = jnp.where(accepted, passed, carry.next_save)
        slot = jnp.where(passed > carry.next_save, carry.next_save, saves)
        slots = jax.tree_util.tree_map(
            lambda buffer, x: buffer.at[slot].set(x), carry.slots, (carry.y, carry.ds)
        )
        moved = (y1, solver_state, ds_next, carry.steps + 1,
                 carry.rejected + (1 - jnp.asarray(accepted, jnp.int32)), passed)  # fmt: skip
        # Past the last save time the state stays put; the slots need no freezing
        # (a frozen step writes only to the spare slot).
        done = carry.next_save >= saves
        kept = jax.tree_util.tree_map(
            lambda a, b: jnp.where(done, a, b), carry[:6], moved
        )
        return _Carry(*kept, slots), None  # pyright: ignore[reportCallIssue]

    slots0 = jax.tree_util.tree_map(
        lambda x: jnp.full((saves + 2, *jnp.shape(x)), jnp.nan, x.dtype), (y0, ds)
    )
    counts = jnp.zeros((), jnp.int32)
    first = jnp.searchsorted(save_ts, t0, side="left").astype(jnp.int32)
    carry = _Carry(y0, solver_state0, ds, counts, counts, first, slots0)
    carry, _ = lax.scan(step, carry, None, length=max_steps)
    starts, steps = _fill_forward(carry.slots, saves)
    return starts, steps, carry.steps, carry.rejected, carry.next_save >= saves


@eqx.filter_jit
def _compiled_run(system, y0, args, solver, t0, ds, save_ts, max_steps):
    """The loop, the partial steps to the save times, and the `Trajectory`."""
    terms = solver.terms(system)
    splitting = solver.splitting
    state0 = extended_state(system, y0, t0, args)
    landing_step = None
    if solver.precision == "double-double":
        advance, landing_step, start = double_double_steps(terms, splitting, args)
        state0, solver_state0 = start(state0)
    else:
        advance = _stepper(terms, splitting, args)
        solver_state0 = splitting.init(terms, jnp.zeros((), ds.dtype), ds, state0, args)
    if max_steps is None:
        run = _walk_to_saves(advance, state0, solver_state0, ds, save_ts)
    else:
        run = _fixed_steps_to_saves(
            advance, state0, solver_state0, ds, save_ts, t0, max_steps
        )
    starts, steps, taken, rejected, reached = run
    one_step = _one_step(terms, splitting, args)

    def to_save(y, tau, ds):
        if landing_step is None:
            return _partial_step(one_step, y, tau, ds)
        # Double-double: σ by float64 secant iterations from the rounded start,
        # then the step itself in double-double (`time_transformed_double_double`).
        step = landing_step
        landing = lambda sigma: rounded_tree(step(y, sigma * ds))
        return _partial_step(one_step, rounded_tree(y), tau, ds, landing)

    (p, _), (q, t_landed) = jax.vmap(to_save)(starts, save_ts, steps)
    result = diffrax.RESULTS.where(
        reached, diffrax.RESULTS.successful, diffrax.RESULTS.max_steps_reached
    )
    stats = dict(
        num_steps=taken,
        num_accepted_steps=taken - rejected,
        num_rejected_steps=rejected,
        time_residual=jnp.max(jnp.abs(t_landed - save_ts)),
        energy_start=-rounded_tree(state0)[0][1],
    )
    return Trajectory(
        ts=save_ts,
        ys=(q, p),
        system=system,
        args=args,
        run_stats=stats,
        result=result,
        solver_name=solver.name,
    )


def _fill_forward(slots: Any, saves: int) -> Any:
    """Slot k holds the start of the step that crosses save time k: where several
    save times fall in one step only the first slot was written; the others take
    the last written slot before them (NaN where none was: not reached)."""
    written = ~jnp.isnan(_time(slots[0])[:saves])
    index = lax.cummax(jnp.where(written, jnp.arange(saves), -1))
    source = jnp.where(index >= 0, index, saves + 1)  # the never-written slot
    return jax.tree_util.tree_map(lambda buffer: buffer[source], slots)


def _one_step(terms: Any, splitting: Any, args: Any):
    """`one_step(y, h) -> y1`: one step of the method of fictitious length h."""

    def one_step(y, h):
        zero = jnp.zeros((), h.dtype)
        state = splitting.init(terms, zero, h, y, args)
        y1, *_ = splitting.step(terms, zero, h, y, args, state, False)
        return y1

    return one_step


def _partial_step(one_step, y, tau, ds, landing=None):
    """Φ_{σ ds}(y) with σ solved by the secant method so that it ends at time tau.

    t(σ) is nearly linear, so from σ = 0 (t = t_n, no step needed) and σ = 1 the
    secant iterates reach round-off in four or five evaluations. One copy of the
    step in one loop body (Newton with `jvp` compiled about three times longer).
    `landing(σ)`, when given, takes the final step instead of `one_step` (the
    double-double run: σ from float64 iterations, the step itself in
    double-double).
    """

    def advance(sigma):
        return one_step(y, sigma * ds)

    def secant(_, carry):
        (sigma_old, t_old), (sigma, _) = carry
        y_sigma = advance(sigma)
        t_sigma = _time(y_sigma)
        slope = t_sigma - t_old
        flat = slope == 0  # converged: keep σ (and a safe division for grad)
        update = (tau - t_sigma) * (sigma - sigma_old) / jnp.where(flat, 1, slope)
        new_sigma = jnp.clip(sigma + jnp.where(flat, 0, update), -0.5, 1.5)
        return (sigma, t_sigma), (new_sigma, y_sigma)

    one = jnp.ones((), ds.dtype)
    start = ((0 * one, _time(y)), (one, y))
    # fori_loop with a fixed trip count is a scan: reverse mode runs through it.
    (sigma, _), (_, landed) = lax.fori_loop(0, SECANT_ITERATIONS, secant, start)
    return landed if landing is None else landing(sigma)
