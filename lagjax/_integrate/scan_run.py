"""The fixed-step runs of `simulate` on lagjax's own scans (`plan.Saving`).

Three savings, one entry point: the final state (one `lax.scan` over the
solver's `step`), every k-th step (nested scans) and states between steps (scans
with a continuous extension, `scan_saving`). The loops themselves live in
`fixed_step_loop` (or, for `lj.ReversibleAdjoint`, in the adjoint); this module
turns their outputs into saved times, states, statistics and a verdict.
"""

from __future__ import annotations

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._integrate.checks.run_verdict import NON_FINITE_MESSAGE
from lagjax._integrate.fixed_step_loop import (
    integrate_every_step,
    integrate_fixed_steps,
    integrate_fixed_steps_saving,
)
from lagjax._integrate.off_grid_saves import integrate_off_grid
from lagjax._integrate.plan import RunPlan, Saving
from lagjax._integrate.reversible_adjoint import ReversibleAdjoint
from lagjax._integrate.scan_saving import integrate_saving
from lagjax._integrate.time_grid import grid_step
from lagjax.solvers.implicit import stage_failure_message


def integrate_on_scans(terms, solver, state0, args, run: RunPlan, mode: Saving):
    """The fixed-step path: `lax.scan`s over the solver's step, saving by `mode`.

    A failed run (a failed implicit solve, a non-finite state) keeps what it
    computed: the final-state run returns the last good state at the time it was
    reached, a saving run its saves up to the failure, with the later ones marked
    as diffrax marks unused slots (t = inf, states inf).
    """
    step = grid_step(run.t0, run.t1, run.dt, run.dtype)
    interpolation = None
    fixed_steps, fixed_steps_saving, off_grid, every_step = (
        (run.adjoint.fixed_steps, run.adjoint.fixed_steps_saving,
         run.adjoint.off_grid_saves, run.adjoint.every_step)
        if isinstance(run.adjoint, ReversibleAdjoint)
        else (integrate_fixed_steps, integrate_fixed_steps_saving, integrate_off_grid,
              integrate_every_step)
    )  # fmt: skip
    if mode is Saving.BETWEEN_STEPS:
        plan = run.saving()
        assert plan is not None  # saving_mode() checked it
        saved_ts, ys, result, steps, interpolation = integrate_saving(
            terms, solver, state0, args, plan, run.t0, run.t1, run.dtype, off_grid,
            every_step,
        )  # fmt: skip
    elif mode is Saving.FINAL_STATE:
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
        assert grid is not None  # saving_mode() checked it
        ys, result, steps, saved = fixed_steps_saving(
            terms, solver, run.t0, step, grid, state0, args, run.dtype
        )
        saved_ts = jnp.where(saved, run.ts, jnp.inf)
        ys = jax.tree_util.tree_map(
            lambda x: jnp.where(saved.reshape((-1,) + (1,) * (x.ndim - 1)), x, jnp.inf),
            ys,
        )
    if run.throw:
        ys = eqx.error_if(ys, result == diffrax.RESULTS.nonfinite, NON_FINITE_MESSAGE)
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
