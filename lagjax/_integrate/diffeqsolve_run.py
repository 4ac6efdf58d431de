"""The general runs of `simulate`: `diffrax.diffeqsolve` (`plan.Saving.DIFFRAX`).

Adaptive steps, step-size controllers, events, diffrax's adjoints, progress
meters and any saving lagjax's scans do not cover. A fixed-step lagjax solver that
must give states between its steps is wrapped in its Hermite continuous
extension (`lagjax.solvers.hermite`) for this run only.
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._integrate.plan import RunPlan
from lagjax._integrate.step_control import diffrax_step_bound, stepping
from lagjax.solvers.hermite import HermiteDenseOutput, needs_hermite


def integrate_with_diffeqsolve(terms, solver, state0, args, run: RunPlan):
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
