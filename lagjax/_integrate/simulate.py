"""`simulate`: integrate a mechanical system with a diffrax solver into a `Trajectory`.

One entry point for every system and solver:

| system | solver | integrated state, terms |
|---|---|---|
| `Lagrangian` | any non-partitioned solver (Tsit5, Dopri8, Kvaerno5, …) | (q, q̇), one `ODETerm` with q̈ from Euler–Lagrange |
| `Lagrangian` | symplectic (GaussLegendre, ImplicitMidpoint) | (q, p) of its Legendre-transformed Hamiltonian |
| `Lagrangian` | `VariationalMidpoint` | (q, p), discrete Euler–Lagrange equations of L |
| any Hamiltonian | non-partitioned | (q, p), one `ODETerm` with Hamilton's equations |
| `SeparableHamiltonian` | partitioned (StormerVerlet, Yoshida4, …) | (q, p), terms (∂T/∂p, −∂V/∂q) |
| `RigidBody` | rigid-body splittings, or any solver | (unit quaternion, body angular momentum), `RigidBodyTerm` |
| constrained `Lagrangian` | any non-partitioned diffrax solver, wrapped in `ConstraintProjection` | (q, q̇), `ConstrainedLagrangianTerm` |
| constrained `Lagrangian` | `Rattle` (holonomic, constant mass matrix) | (q, p), `RattleTerm` |

Which terms and state each system gets for a solver is the system's own answer
(`lagjax._core.system.AbstractSystem.integration`). A solver is *partitioned* when its diffrax `term_structure` is a pair of terms
(lagjax's splitting methods and diffrax's `SemiImplicitEuler`). With `dt` the steps are
fixed; without it the solver must be adaptive and `rtol`/`atol` control the error.
Only the final state is saved unless `ts` (or `saveat`) asks for more. Fixed steps
with only the final state saved, or `ts` on a uniform subgrid of the steps (and the
default adjoint), run as plain `lax.scan`s over the solver's `step` (see
`fixed_step.py`); everything else runs through `diffrax.diffeqsolve`. A run that
reads states between steps (`ts` off the grid, `dense=True`, an `event`) gives a
fixed-step solver a Hermite continuous extension (`lagjax.solvers.hermite`) for that run
only; `Trajectory.evaluate` and event conditions see `y0`'s convention
(`lagjax._integrate.dense_output`).

The arguments are checked in Python (`lagjax._integrate.checks.inputs`), and all the numeric
work — casting to the working precision, flattening, the loop, the diagnosis
after it — runs as one compiled call (`_compiled_run`), so a first call compiles
about as often as `diffeqsolve` does and a second call with another `y0` compiles
nothing.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from lagjax._core.precision import (
    cast_floats,
    python_floats_as_arrays,
    working_dtype,
)
from lagjax._core.static_values import Constant
from lagjax._core.system import AbstractSystem
from lagjax._integrate.checks.inputs import check_simulate_inputs
from lagjax._integrate.checks.late_failure import raise_if_failed
from lagjax._integrate.checks.run_verdict import (
    NON_FINITE_MESSAGE as _NON_FINITE_MESSAGE,
)
from lagjax._integrate.checks.run_verdict import judge_run
from lagjax._integrate.dense_output import DenseSolution, UserState, event_in_user_state
from lagjax._integrate.fixed_step_loop import (
    fixed_step_count,
    integrate_fixed_steps,
    integrate_fixed_steps_saving,
    uniform_grid_saves,
)
from lagjax._integrate.flat_state import flattened
from lagjax._integrate.reversible_adjoint import (
    ReversibleAdjoint,
    check_reversible_run,
)
from lagjax._integrate.scan_saving import ScanSaving, integrate_saving, scan_saving
from lagjax._integrate.solver_choice import chosen_solver
from lagjax._integrate.step_control import (
    as_python_number,
    defaults,
    diffrax_step_bound,
    stepping,
    with_implicit_tolerances,
)
from lagjax._integrate.taylor_run import run_taylor
from lagjax._integrate.time_grid import grid_step
from lagjax._integrate.time_transformed_run import run_time_transformed
from lagjax.solvers.hermite import HermiteDenseOutput, needs_hermite
from lagjax.solvers.implicit import stage_failure_message
from lagjax.solvers.time_transformed import TimeTransformed
from lagjax.taylor.solver import Taylor
from lagjax.trajectory import Trajectory

System = AbstractSystem


def simulate(
    system: System,
    y0: tuple[Any, Any],
    t0: float = 0.0,
    t1: float | None = None,
    dt: float | None = None,
    solver: diffrax.AbstractSolver | None = None,
    ts: Any = None,
    args: Any = None,
    rtol: float = 1e-8,
    atol: float = 1e-8,
    max_steps: int | None = None,
    progress: bool = False,
    *,
    saveat: diffrax.SaveAt | None = None,
    adjoint: diffrax.AbstractAdjoint | ReversibleAdjoint | None = None,
    throw: bool = True,
    dense: bool = False,
    event: diffrax.Event | None = None,
    stepsize_controller: diffrax.AbstractStepSizeController | None = None,
    progress_meter: diffrax.AbstractProgressMeter | None = None,
) -> Trajectory:
    """Integrate `system` from `y0` over [t0, t1].

    **Arguments:**
    - `system`: any `AbstractSystem`: a `Lagrangian`, `Hamiltonian`,
      `SeparableHamiltonian` (or `LegendreHamiltonian`), `RigidBody`, or a scene
      (`lagjax.scenes`), whose parameters are then passed as `args` unless `args`
      is given.
    - `y0`: `(q0, qdot0)` for a Lagrangian, `(q0, p0)` for a Hamiltonian.
    - `t1`: end time; default 10, or a scene's `default_t1`.
    - `dt`: fixed step; None for adaptive stepping with `rtol`, `atol` — except
      for a scene run by its default (or another fixed-step) solver, which then
      steps by the scene's `default_dt`.
    - `solver`: any diffrax solver or lagjax solver; None picks one by structure
      (`lagjax._integrate.solver_choice`) and records it in `stats["solver"]`.
    - `ts`: times to save at; default only the final state. `saveat` overrides.
    - `max_steps`: default: the exact count for fixed steps, 10⁵ adaptive.
    - `progress`: show diffrax's text progress meter.
    - `adjoint`: diffrax adjoint; pass `diffrax.ForwardMode()` to use `jax.jvp` /
      `jax.jacfwd` through the solve (reverse mode works with the default);
      `lj.ReversibleAdjoint()` for reverse mode in constant memory through a
      fixed-step run of a time-reversible solver
      (`lagjax._integrate.reversible_adjoint`).
    - `dense`: keep the continuous extension: `traj.evaluate(t)` gives the state
      at any t of the span (`saveat=diffrax.SaveAt(dense=True)` does too).
      Fixed-step lagjax solvers get a Hermite extension of their order up to 4
      (6 for orders above 4; `lagjax.solvers.hermite`), used for `ts` off the step grid
      and events too.
    - `event`: a `diffrax.Event`; its `cond_fn(t, y, args, **kwargs)` sees `y` in
      `y0`'s convention. The run ends at the first event, located on the dense
      output (Newton's method when the event names no root finder);
      `traj.result` is then `RESULTS.event_occurred` and
      `traj.stats["event_mask"]` says which condition fired.
    - `stepsize_controller`: any diffrax controller (`PIDController`, `StepTo`,
      `ConstantStepSize`); it replaces `rtol`/`atol`. An adaptive one needs a
      solver with an error estimate.
    - `progress_meter`: any diffrax progress meter (replaces `progress`).
    - `throw`: raise on failure (max_steps reached, failed implicit solve, non-finite
      state). With False the trajectory up to the failure is returned and
      `result`/`stats["finite"]` say what happened; on the fixed-step path the
      final state is the last good one, at the time it was reached, and saves
      after the failure are marked t = inf (as diffrax marks unused slots). A
      fixed-step run of a conservative system whose energy left any sane bound
      (`lagjax._integrate.checks.run_verdict`) is a failure too: `RESULTS.nonlinear_divergence`, and
      `stats["energy_drift"]` holds the measured ratio.
    """
    if isinstance(solver, Taylor):  # Taylor series of the derived equations
        return run_taylor(system, y0, t0, t1, dt, solver, ts, args, rtol, atol,
                          max_steps, throw, saveat=saveat, adjoint=adjoint,
                          dense=dense, event=event, progress=progress,
                          stepsize_controller=stepsize_controller,
                          progress_meter=progress_meter)  # fmt: skip
    if isinstance(solver, TimeTransformed):  # dt is the fictitious step ds
        return run_time_transformed(system, y0, t0, t1, dt, solver, ts, args,
                                    max_steps, throw, saveat=saveat, adjoint=adjoint,
                                    dense=dense, event=event, progress=progress,
                                    stepsize_controller=stepsize_controller,
                                    progress_meter=progress_meter)  # fmt: skip
    t1, dt = defaults(system, t0, t1, dt, solver, stepsize_controller)
    y0 = check_simulate_inputs(system, y0, t0, t1, dt, solver, ts, args, max_steps)
    if progress and progress_meter is not None:
        raise ValueError("pass progress=True or progress_meter, not both")
    t0, t1, dt = (as_python_number(x) for x in (t0, t1, dt))
    if not isinstance(system, AbstractSystem):
        raise TypeError(
            "simulate needs a lagjax system (Lagrangian, Hamiltonian, "
            f"SeparableHamiltonian, RigidBody or a scene); got {type(system).__name__}"
        )
    # A scene's parameters are its fields; its physics reads them from args.
    system, args = system.resolve(args)
    # The run works in y0's precision; float inputs follow it (lagjax._core.precision).
    dtype = working_dtype(y0)
    # Python floats would be static parts of the compiled program: one compilation
    # per value (`lagjax._core.precision.python_floats_as_arrays`).
    y0, args = python_floats_as_arrays((y0, args), dtype)
    solver = chosen_solver(system, solver, dt, rtol)
    system.check_start(y0, t0, args, dtype)
    if dt is not None or not isinstance(
        stepsize_controller, (diffrax.AbstractAdaptiveStepSizeController, type(None))
    ):
        solver = with_implicit_tolerances(solver, rtol, atol)
    # A concrete adaptive run is diagnosed after its compiled call, in one plain
    # error that keeps what was computed (`checks.late_failure`).
    late = throw and dt is None and not _traced(system, y0, args, ts)
    run = _Run(t0, t1, dt, _save_times(ts, dtype), rtol, atol, max_steps, progress,
               saveat, adjoint, throw and not late, dtype, dense, event,
               stepsize_controller, progress_meter)  # fmt: skip
    scan = run.fits_scan()
    check_reversible_run(adjoint, solver, scan and run.saves_on_grid(), dt)
    trajectory = _compiled_run(
        system, y0, args, solver, _for_compiled_call(run, scan), scan
    )
    if late:
        trajectory = raise_if_failed(trajectory, trajectory.stats["max_steps"], rtol)
    return trajectory


def _traced(*trees: Any) -> bool:
    leaves = jax.tree_util.tree_leaves(trees)
    return any(isinstance(leaf, Tracer) for leaf in leaves)


@eqx.filter_jit
def _compiled_run(system, y0, args, solver, run: _Run, scan: bool) -> Trajectory:
    """All the numeric work of a run as ONE compiled call: casting, flattening, the
    loop, and the diagnosis after it (`lagjax._integrate.checks.run_verdict.judge_run`).

    Run eagerly, each small step before and after the loop (a cast, a ravel, a
    finiteness test) compiled and dispatched its own XLA computation: 21
    compilations for a first adaptive run of the double pendulum, where diffeqsolve
    on hand-written equations needs 3. Arrays are traced arguments, so a new `y0`,
    `args` or system parameter of the same shapes reuses the compilation; the
    configuration — solver, saving, tolerances and the Python numbers t0, t1, dt —
    is static, as in a hand-written jitted `diffeqsolve`: XLA compiles the adaptive
    loop over a constant span in about half the time it takes over a traced one.
    """
    dtype = run.dtype
    y0, system, args = (
        cast_floats(y0, dtype),
        cast_floats(system, dtype),
        cast_floats(args, dtype),
    )
    if isinstance(run.ts, Constant):  # the scan path (`_for_compiled_call`)
        saveat: Any = run.saveat
        run = run._replace(ts=run.ts.value, saveat=saveat.value)
    elif run.ts is not None:
        run = run._replace(ts=jnp.asarray(run.ts, dtype=dtype))
    terms, state0, integrated = system.integration(solver, y0, run.t0, args)
    # One vector is what diffrax's loops run fastest (lagjax._integrate.flat_state).
    start = state0
    terms, state0, flat = flattened(terms, state0, run.saveat)
    user_state = UserState.of(flat, integrated, system)
    if run.event is not None:
        run = run._replace(event=event_in_user_state(run.event, user_state, dtype))
    integrate = _integrate_scan if scan else _diffeqsolve
    saved_ts, ys, stats, result, interpolation = integrate(
        terms, solver, state0, args, run
    )
    if flat is not None:
        ys = flat.unravel(ys)
    ys, result, checks = judge_run(
        integrated, start, run.t0, saved_ts, ys, args, result,
        fixed_steps=run.dt is not None and run.saveat is None, throw=run.throw,
    )  # fmt: skip
    return Trajectory(
        ts=saved_ts,
        ys=ys,
        system=integrated,
        args=args,
        run_stats={**stats, **checks},
        result=result,
        solver_name=type(solver).__name__,
        dense_output=None
        if interpolation is None
        else DenseSolution(interpolation, user_state, args),
    )


def _save_times(ts: Any, dtype: Any) -> Any:
    """`ts` in the run's dtype: a NumPy array when concrete (no device work before
    the compiled call), a tracer as it is."""
    if ts is None or isinstance(ts, Tracer):
        return ts
    return np.asarray(ts, dtype=dtype)


def _for_compiled_call(run: _Run, scan: bool) -> _Run:
    """`run` as `_compiled_run` takes it: the scan path lays out its loops in Python
    from the save times, so they travel as static constants
    (`lagjax._core.static_values`)."""
    if not scan:
        return run
    # Concrete even when simulate is traced (inside a user's jit, device_put is
    # staged like any operation).
    with jax.ensure_compile_time_eval():
        ts = None if run.ts is None else jax.device_put(run.ts)
    return run._replace(ts=Constant(ts), saveat=Constant(run.saveat))


class _Run(NamedTuple):
    """How `simulate` was asked to integrate: times, tolerances, saving, adjoint."""

    t0: Any
    t1: Any
    dt: Any
    ts: Any
    rtol: float
    atol: float
    max_steps: int | None
    progress: bool
    saveat: diffrax.SaveAt | None
    adjoint: diffrax.AbstractAdjoint | None
    throw: bool
    dtype: Any
    dense: bool = False
    event: diffrax.Event | None = None
    controller: diffrax.AbstractStepSizeController | None = None
    progress_meter: diffrax.AbstractProgressMeter | None = None

    def fits_scan(self) -> bool:
        """Fixed steps, default adjoint, no progress meter, step-size controller or
        event, and a saving the scans cover (`scan_saving`): the scan path."""
        plain = (
            self.dt is not None
            and (self.adjoint is None or isinstance(self.adjoint, ReversibleAdjoint))
            and not self.progress
            and self.event is None
            and self.controller is None
            and self.progress_meter is None
            and all(isinstance(x, (int, float)) for x in (self.t0, self.t1, self.dt))
        )
        return plain and (self.saves_on_grid() or self.saving() is not None)

    def saves_on_grid(self) -> bool:
        """Only the final state, or `ts` on a uniform subgrid of the steps."""
        plain = self.saveat is None and self.max_steps is None and not self.dense
        return plain and (self.ts is None or self.save_grid() is not None)

    def saving(self) -> ScanSaving | None:
        return scan_saving(self.t0, self.t1, self.dt, self.ts, self.saveat,
                           self.dense, self.max_steps, self.dtype)  # fmt: skip

    def save_grid(self) -> tuple[int, int, int] | None:
        """`(lead, every, saves)` of `ts` on the step grid within [t0, t1], or None
        (traced `ts`, off the grid, or unevenly spaced)."""
        try:
            ts = np.asarray(self.ts, dtype=float)
        except jax.errors.TracerArrayConversionError:
            return None
        grid = uniform_grid_saves(self.t0, self.dt, ts)
        if grid is None:
            return None
        lead, every, saves = grid
        if lead + every * (saves - 1) > fixed_step_count(self.t0, self.t1, self.dt):
            return None
        return grid


def _integrate_scan(terms, solver, state0, args, run: _Run):
    """The fixed-step path: `lax.scan`s over the solver's step (`fixed_step.py`).

    A failed run (a failed implicit solve, a non-finite state) keeps what it
    computed: the final-state run returns the last good state at the time it was
    reached, a saving run its saves up to the failure, with the later ones marked
    as diffrax marks unused slots (t = inf, states inf).
    """
    step = grid_step(run.t0, run.t1, run.dt, run.dtype)
    interpolation = None
    fixed_steps, fixed_steps_saving = (
        (run.adjoint.fixed_steps, run.adjoint.fixed_steps_saving)
        if isinstance(run.adjoint, ReversibleAdjoint)
        else (integrate_fixed_steps, integrate_fixed_steps_saving)
    )
    if not run.saves_on_grid():
        plan = run.saving()
        assert plan is not None  # fits_scan() checked it
        saved_ts, ys, result, steps, interpolation = integrate_saving(
            terms, solver, state0, args, plan, run.t0, run.t1, run.dtype
        )
    elif run.ts is None:
        y1, result, steps = fixed_steps(
            terms, solver, run.t0, run.t1, step, state0, args, run.dtype
        )
        signed = math.copysign(abs(step), run.t1 - run.t0)
        reached = jnp.where(
            result == diffrax.RESULTS.successful, run.t1, run.t0 + steps * signed
        )
        saved_ts = jnp.asarray(reached, dtype=run.dtype)[None]
        ys = jax.tree_util.tree_map(lambda x: jnp.asarray(x)[None], y1)
    else:
        step = math.copysign(abs(step), run.t1 - run.t0)
        grid = run.save_grid()
        assert grid is not None  # fits_scan() checked it
        ys, result, steps, saved = fixed_steps_saving(
            terms, solver, run.t0, step, grid, state0, args, run.dtype
        )
        saved_ts = jnp.where(saved, run.ts, jnp.inf)
        ys = jax.tree_util.tree_map(
            lambda x: jnp.where(saved.reshape((-1,) + (1,) * (x.ndim - 1)), x, jnp.inf),
            ys,
        )
    if run.throw:
        ys = eqx.error_if(ys, result == diffrax.RESULTS.nonfinite, _NON_FINITE_MESSAGE)
        # diffrax's text cannot say why a stage solve failed; the solver can.
        stage_failed = (result == diffrax.RESULTS.nonlinear_max_steps_reached) | (
            result == diffrax.RESULTS.nonlinear_divergence
        )
        ys = eqx.error_if(ys, stage_failed, stage_failure_message(solver))
        ys = result.error_if(ys, result != diffrax.RESULTS.successful)
    counts = jnp.asarray(steps)
    stats = dict(
        num_steps=counts, num_accepted_steps=counts, num_rejected_steps=0 * counts
    )
    return saved_ts, ys, stats, result, interpolation


def _diffeqsolve(terms, solver, state0, args, run: _Run):
    """The general path: `diffrax.diffeqsolve` with saving, adjoints, adaptivity."""
    t0, t1, dt, ts, dtype = run.t0, run.t1, run.dt, run.ts, run.dtype
    controller, dt0 = stepping(solver, t0, t1, dt, run.rtol, run.atol, run.controller)
    max_steps = run.max_steps
    if max_steps is None:
        fixed = run.controller is None or isinstance(
            run.controller, diffrax.ConstantStepSize
        )
        max_steps = (fixed and diffrax_step_bound(t0, t1, dt)) or 100_000
    # diffrax promotes the state to the dtype of the times: give it the state's.
    t0, t1 = jnp.asarray(t0, dtype=dtype), jnp.asarray(t1, dtype=dtype)
    dt0 = None if dt0 is None else jnp.asarray(dt0, dtype=dtype)
    saveat = run.saveat
    if saveat is None:
        saveat = diffrax.SaveAt(ts=ts) if ts is not None else diffrax.SaveAt(t1=True)
    if run.dense:
        saveat = eqx.tree_at(lambda s: s.dense, saveat, True)
    if needs_hermite(solver) and _interpolates(saveat, run.event):
        solver = HermiteDenseOutput.for_solver(solver, terms)
    if run.progress_meter is not None:
        meter = run.progress_meter
    else:
        meter = (
            diffrax.TextProgressMeter() if run.progress else diffrax.NoProgressMeter()
        )
    solution = diffrax.diffeqsolve(
        terms,
        solver,
        t0,
        t1,
        dt0,
        state0,
        args=args,
        saveat=saveat,
        stepsize_controller=controller,
        max_steps=max_steps,
        adjoint=diffrax.RecursiveCheckpointAdjoint()
        if run.adjoint is None
        else run.adjoint,
        progress_meter=meter,
        event=run.event,
        throw=run.throw,
    )
    if solution.ts is None or solution.ys is None:
        raise ValueError("saveat must save at least one state (t0, t1, ts or steps)")
    # Arrays only, so trajectories batch under vmap and jit.
    stats: dict[str, Any] = {
        key: jnp.asarray(value) for key, value in solution.stats.items()
    }
    if run.event is not None:
        stats["event_mask"] = solution.event_mask
    return solution.ts, solution.ys, stats, solution.result, solution.interpolation


def _interpolates(saveat: diffrax.SaveAt, event: diffrax.Event | None) -> bool:
    """Whether a run reads states between steps: saves at given times, dense
    output, or an event to locate."""
    subs = jax.tree_util.tree_leaves(
        saveat.subs, is_leaf=lambda x: isinstance(x, diffrax.SubSaveAt)
    )
    return saveat.dense or event is not None or any(s.ts is not None for s in subs)
