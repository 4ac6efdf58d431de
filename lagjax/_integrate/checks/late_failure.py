"""A failed adaptive run, told after its compiled call: what failed, the remedy that
fits the call, and what was computed.

Inside a compiled run a failure can only be raised by `eqx.error_if`, whose message
arrives at the end of two stack traces. When `simulate` is called on concrete
values (not under the user's `jit`), the adaptive run is compiled with
`throw=False` and, if it failed, this module raises one `SimulationError` instead:
its message names the failure and the remedy, and its `trajectory` holds the states
up to the failure (diffrax's unused save slots are marked t = inf).

A run out of steps is told apart by why: a step-size collapse (nearly every step
rejected — a singular mass matrix or a NaN in the equations; more steps cannot
help), tolerances at the resolution of the working precision, or a plain lack of
budget (then: raise max_steps, loosen the tolerances, or a higher-order method).
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import numpy as np
from jax.core import Tracer

from lagjax._integrate.checks.run_verdict import DIVERGENCE_MESSAGE, NON_FINITE_MESSAGE


class SimulationError(eqx.EquinoxRuntimeError):
    """A run that failed; `trajectory` holds what was computed before the failure."""

    def __init__(self, message: str, trajectory: Any):
        super().__init__(message)
        self.trajectory = trajectory


def _max_steps_message(trajectory: Any, max_steps: Any, rtol: float) -> str:
    # the last save with a state: unused slots are t = inf (diffrax) or NaN states
    states = np.concatenate(
        [np.asarray(x).reshape(len(np.asarray(trajectory.ts)), -1)
         for x in jax.tree_util.tree_leaves(trajectory.ys)], axis=1,
    )  # fmt: skip
    times = np.asarray(trajectory.ts)
    kept = np.isfinite(times) & np.all(np.isfinite(states), axis=1)
    last = int(np.flatnonzero(kept)[-1]) if kept.any() else None
    where = "" if last is None else f" (last saved state at t = {times[last]:.6g})"
    solver = trajectory.stats.get("solver", "the solver")
    steps = int(np.asarray(max_steps))
    rejected = int(np.asarray(trajectory.stats.get("num_rejected_steps", 0)))
    if rejected > STALL_REJECTED_FRACTION * steps:
        return (
            f"simulate stalled{where} before reaching t1 ({solver}, rtol = "
            f"{rtol:g}): the step size collapsed — {rejected} of its {steps} steps "
            "were rejected — so raising max_steps will not help. The equations of "
            "motion are singular or not finite there"
            f"{_rate_there(trajectory, last)}: a mass matrix ∂²L/∂q̇² that "
            "becomes singular (a coordinate singularity, a degenerate L), a "
            "collision or singular potential, or a NaN/inf that L or H produces. "
            "The states up to there are in this error's .trajectory "
            "(simulate(..., throw=False) returns them instead of raising)."
        )
    advice = (
        "raise max_steps (simulate(..., max_steps=N)), loosen rtol/atol, or use a "
        "higher-order method"
    )
    eps = float(np.finfo(times.dtype).eps)
    if rtol < 10 * eps:
        advice = (
            f"rtol = {rtol:g} is at the resolution of {times.dtype} (ε = {eps:.2g}), "
            f"where the error estimate is round-off: pass rtol ≥ {10 * eps:.1g}"
            + (" or run in float64" if times.dtype.itemsize < 8 else "")
        )
    elif rtol < 1e-9 and solver in {"Tsit5", "Dopri5", "Euler", "Heun", "Bosh3"}:
        advice = (
            f"{solver} is a low-order method and rtol = {rtol:g} asks for many tiny "
            "steps: pass solver=diffrax.Dopri8() (or lj.Taylor()), or raise max_steps"
        )
    return (
        f"simulate stopped after max_steps = {steps} steps{where} "
        f"before reaching t1 ({solver}, rtol = {rtol:g}): {advice}. The states up to "
        "there are in this error's .trajectory (simulate(..., throw=False) returns "
        "them instead of raising)."
    )


# A run out of steps with more than this fraction of them rejected did not run
# out of budget: its step size collapsed (a healthy adaptive run rejects a few
# per cent; a mass matrix vanishing at t = 0.5 rejected 99 704 of 100 000).
STALL_REJECTED_FRACTION = 0.9


def _rate_there(trajectory: Any, last: int | None) -> str:
    """How fast the state moves at the last saved state, when that shows the
    singularity: ' (… not finite …)' or ' (… a rate of R against a size of S …)'
    when S/R is under 10⁻⁶ of the time covered so far; else ''."""
    if last is None:
        return ""
    t = trajectory.ts[last]
    state = jax.tree_util.tree_map(lambda x: x[last], trajectory.ys)
    rate = trajectory.system.state_rate(*state, t, trajectory.args)
    rate = np.concatenate([np.ravel(x) for x in jax.tree_util.tree_leaves(rate)])
    size = max(np.max(np.abs(np.concatenate(
        [np.ravel(x) for x in jax.tree_util.tree_leaves(state)]
    ))), np.finfo(rate.dtype).tiny)  # fmt: skip
    if not np.all(np.isfinite(rate)):
        return f" (the rate of change of the state is not finite at t = {float(t):.6g})"
    # the time the run had covered: the span's own scale (t1 is not kept)
    span = max(abs(float(t)), abs(float(t) - float(trajectory.ts[0]))) or 1.0
    speed = float(np.max(np.abs(rate)))
    if speed * span < STALL_RATE * size:
        return ""
    return (
        f" (at t = {float(t):.6g} the state, of size {size:.2g}, changes at a rate "
        f"of {speed:.2g})"
    )


# A rate that would cross the state's own size this many times over the span marks
# the singularity the steps could not pass.
STALL_RATE = 1e6


def raise_if_failed(trajectory: Any, max_steps: Any, rtol: float) -> Any:
    """Raise `SimulationError` when a concrete adaptive run did not succeed; return
    the trajectory. Inside a caller's own `jit` (concrete inputs closed over, traced
    outputs) nothing can be raised now: the failure is attached to the trajectory
    as diffrax's run-time error (`eqx.error_if`), as a traced run does."""
    succeeded = trajectory.run_stats.get("succeeded")
    if isinstance(succeeded, Tracer):
        trajectory = eqx.error_if(
            trajectory, ~trajectory.run_stats["finite"], NON_FINITE_MESSAGE
        )
        return trajectory.result.error_if(trajectory, ~succeeded)
    if succeeded is not None and bool(np.asarray(succeeded)):
        return trajectory
    result = trajectory.result
    finite = bool(np.asarray(trajectory.run_stats.get("finite", True)))
    ended = (
        result == diffrax.RESULTS.successful or result == diffrax.RESULTS.event_occurred
    )
    if ended and finite:
        return trajectory
    # out of steps first: the saves not reached are NaN, not a failure of their own
    if result == diffrax.RESULTS.max_steps_reached:
        message = _max_steps_message(trajectory, max_steps, rtol)
    elif not finite or result == diffrax.RESULTS.nonfinite:
        message = NON_FINITE_MESSAGE
    elif result == diffrax.RESULTS.nonlinear_divergence and np.isfinite(
        np.asarray(trajectory.stats.get("energy_drift", np.nan))
    ):
        message = DIVERGENCE_MESSAGE
    else:
        message = (
            f"simulate failed: {result}. simulate(..., throw=False) returns the run "
            "instead of raising, to inspect it."
        )
    raise SimulationError(message, trajectory)
