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
Only the final state is saved unless `ts` (or `saveat`) asks for more. Which loop
runs a call — lagjax's scans over the solver's `step` for plain fixed-step runs,
`diffrax.diffeqsolve` for everything else — and how it saves is decided in one
place, `lagjax._integrate.plan`; the loops are `scan_run` and `diffeqsolve_run`.
A run that reads states between steps (`ts` off the grid, `dense=True`, an
`event`) gives a fixed-step solver a Hermite continuous extension
(`lagjax.solvers.hermite`) for that run only; `Trajectory.evaluate` and event
conditions see `y0`'s convention (`lagjax._integrate.dense_output`).

The arguments are checked in Python (`lagjax._integrate.checks.inputs`), and all the numeric
work — casting to the working precision, flattening, the loop, the diagnosis
after it — runs as one compiled call (`_compiled_run`), so a first call compiles
about as often as `diffeqsolve` does and a second call with another `y0` compiles
nothing.
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from lagjax._core.host_callbacks import host_callbacks_explained
from lagjax._core.precision import (
    cast_floats,
    python_floats_as_arrays,
    working_dtype,
)
from lagjax._core.static_values import Constant
from lagjax._core.system import AbstractSystem
from lagjax._integrate.chain_run import run_chain
from lagjax._integrate.checks.forward_mode import forward_mode_explained
from lagjax._integrate.checks.inputs import check_save_choice, check_simulate_inputs
from lagjax._integrate.checks.late_failure import raise_if_failed
from lagjax._integrate.checks.run_verdict import judge_run
from lagjax._integrate.checks.traced_save_times import checked_traced_save_times
from lagjax._integrate.dense_output import DenseSolution, UserState, event_in_user_state
from lagjax._integrate.diffeqsolve_run import integrate_with_diffeqsolve
from lagjax._integrate.flat_state import flattened
from lagjax._integrate.geometric_choice import geometric_default
from lagjax._integrate.plan import RunPlan, Saving
from lagjax._integrate.reversible_adjoint import (
    ReversibleAdjoint,
    check_reversible_run,
)
from lagjax._integrate.scan_run import integrate_on_scans
from lagjax._integrate.solver_choice import chosen_solver
from lagjax._integrate.step_control import (
    as_python_number,
    defaults,
    with_implicit_tolerances,
)
from lagjax._integrate.taylor_heyoka_repeat import run_taylor_reusing_checks
from lagjax._integrate.time_transformed_run import (
    check_no_tolerances_for,
    run_time_transformed,
)
from lagjax._integrate.wisdom_holman_run import run_wisdom_holman
from lagjax.solvers.chain import ChainRegularization
from lagjax.solvers.time_transformed import TimeTransformed
from lagjax.solvers.wisdom_holman import WisdomHolman
from lagjax.taylor.solver import Taylor
from lagjax.trajectory import Trajectory

System = AbstractSystem
# rtol and atol when neither is given.
DEFAULT_TOLERANCE = 1e-8


def simulate(
    system: System,
    y0: tuple[Any, Any],
    t0: float = 0.0,
    t1: float | None = None,
    dt: float | None = None,
    solver: diffrax.AbstractSolver | Taylor | None = None,
    ts: Any = None,
    args: Any = None,
    rtol: float | None = None,
    atol: float | None = None,
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
      for a scene run by its default (or another fixed-step) solver with no
      tolerance given, which then steps by the scene's `default_dt`.
    - `rtol`, `atol`: the tolerances of an adaptive run (default 1e-8 each) and of
      implicit stage solves. Given with no `solver` and no `dt`, they ask for a
      tolerance run, of a scene too.
    - `solver`: any diffrax solver or lagjax solver; None picks one by structure
      (`lagjax._integrate.solver_choice`) and records it in `stats["solver"]`.
    - `ts`: times to save at; default only the final state. Give `ts` or `saveat`,
      not both (refused).
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
    # A tolerance given with no solver asks for a tolerance run, also of a scene
    # (whose default run is otherwise its fixed step: rtol would only tune stage
    # solves there, silently).
    tolerance_run = solver is None and (rtol is not None or atol is not None)
    check_save_choice(ts, saveat)  # before the Taylor and time-transformed routes
    given_tolerances = {"rtol": rtol, "atol": atol}
    rtol = DEFAULT_TOLERANCE if rtol is None else rtol
    atol = DEFAULT_TOLERANCE if atol is None else atol
    options = (saveat, adjoint, event, stepsize_controller, progress_meter)
    if (
        tolerance_run
        and dt is None
        and max_steps is None
        and not (progress or dense)
        and all(option is None for option in options)
    ):  # a gravitating two-body system may run in fictitious time instead
        geometric = geometric_default(system, y0, t0, t1, args, rtol)
        if geometric is not None:
            time_transformed, ds = geometric
            return run_time_transformed(system, y0, t0, t1, ds, time_transformed,
                                        ts, args, max_steps, throw)  # fmt: skip
    if isinstance(solver, Taylor):  # Taylor series of the derived equations
        # a repeated heyoka call reuses its first call's checks and set-up
        return run_taylor_reusing_checks(
            system, y0, t0, t1, dt, solver, ts, args, rtol, atol, max_steps, throw,
            saveat=saveat, adjoint=adjoint, dense=dense, event=event,
            progress=progress, stepsize_controller=stepsize_controller,
            progress_meter=progress_meter,
        )  # fmt: skip
    if isinstance(solver, WisdomHolman):  # Jacobi coordinates, saves on the step grid
        return run_wisdom_holman(system, y0, t0, t1, dt, solver, ts, args, max_steps,
                                 throw, saveat=saveat, adjoint=adjoint, dense=dense,
                                 event=event, progress=progress,
                                 stepsize_controller=stepsize_controller,
                                 progress_meter=progress_meter)  # fmt: skip
    if isinstance(solver, TimeTransformed):  # dt is the fictitious step ds
        check_no_tolerances_for(solver, given_tolerances)
        return run_time_transformed(system, y0, t0, t1, dt, solver, ts, args,
                                    max_steps, throw, saveat=saveat, adjoint=adjoint,
                                    dense=dense, event=event, progress=progress,
                                    stepsize_controller=stepsize_controller,
                                    progress_meter=progress_meter)  # fmt: skip
    if isinstance(solver, ChainRegularization):  # chain coordinates, dt is ds
        return run_chain(system, y0, t0, t1, dt, solver, ts, args, max_steps, throw,
                         given_tolerances, saveat=saveat, adjoint=adjoint, dense=dense,
                         event=event, progress=progress,
                         stepsize_controller=stepsize_controller,
                         progress_meter=progress_meter)  # fmt: skip
    t1, dt = defaults(system, t0, t1, dt, solver, stepsize_controller, tolerance_run)
    y0 = check_simulate_inputs(system, y0, t0, t1, dt, solver, ts, args, max_steps,
                               rtol, atol)  # fmt: skip
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
    plan = RunPlan(t0, t1, dt, _save_times(ts, dtype, t0, t1), rtol, atol, max_steps,
                   progress, saveat, adjoint, throw and not late, dtype, dense, event,
                   stepsize_controller, progress_meter)  # fmt: skip
    mode = plan.saving_mode()
    check_reversible_run(adjoint, solver, plan, mode)
    # jax.jacfwd through diffeqsolve: name the adjoint; a missing CPU for callbacks
    with forward_mode_explained(), host_callbacks_explained():
        trajectory = _compiled_run(
            system, y0, args, solver, plan.for_compiled_call(mode), mode
        )
    if late:
        trajectory = raise_if_failed(trajectory, trajectory.stats["max_steps"], rtol)
    return trajectory


def _traced(*trees: Any) -> bool:
    leaves = jax.tree_util.tree_leaves(trees)
    return any(isinstance(leaf, Tracer) for leaf in leaves)


@eqx.filter_jit
def _compiled_run(system, y0, args, solver, run: RunPlan, mode: Saving) -> Trajectory:
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
    if isinstance(run.ts, Constant):  # the scan path (`RunPlan.for_compiled_call`)
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
    if mode.on_scan:
        integrated_run = integrate_on_scans(terms, solver, state0, args, run, mode)
    else:
        integrated_run = integrate_with_diffeqsolve(terms, solver, state0, args, run)
    saved_ts, ys, stats, result, interpolation = integrated_run
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


def _save_times(ts: Any, dtype: Any, t0: Any, t1: Any) -> Any:
    """`ts` in the run's dtype: a NumPy array when concrete (no device work before
    the compiled call, its values checked before), a tracer with its values checked
    at run time (`checks.traced_save_times`)."""
    if ts is None:
        return ts
    if isinstance(ts, Tracer):
        return checked_traced_save_times(ts, t0, t1)
    return np.asarray(ts, dtype=dtype)
