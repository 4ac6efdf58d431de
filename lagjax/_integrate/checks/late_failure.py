"""A failed adaptive run, told after its compiled call: what failed, the remedy that
fits the call, and what was computed.

Inside a compiled run a failure can only be raised by `eqx.error_if`, whose message
arrives at the end of two stack traces. When `simulate` is called on concrete
values (not under the user's `jit`), the adaptive run is compiled with
`throw=False` and, if it failed, this module raises one `SimulationError` instead:
its message names the failure and the remedy, and its `trajectory` holds the states
up to the failure (diffrax's unused save slots are marked t = inf).
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import numpy as np

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
    where = f" (last saved state at t = {times[kept][-1]:.6g})" if kept.any() else ""
    solver = trajectory.stats.get("solver", "the solver")
    advice = (
        "raise max_steps (simulate(..., max_steps=N)), loosen rtol/atol, or use a "
        "higher-order method"
    )
    if rtol < 1e-9 and solver in {"Tsit5", "Dopri5", "Euler", "Heun", "Bosh3"}:
        advice = (
            f"{solver} is a low-order method and rtol = {rtol:g} asks for many tiny "
            "steps: pass solver=diffrax.Dopri8() (or lj.Taylor()), or raise max_steps"
        )
    return (
        f"simulate stopped after max_steps = {int(np.asarray(max_steps))} steps{where} "
        f"before reaching t1 ({solver}, rtol = {rtol:g}): {advice}. The states up to "
        "there are in this error's .trajectory (or pass throw=False)."
    )


def raise_if_failed(trajectory: Any, max_steps: Any, rtol: float) -> Any:
    """Raise `SimulationError` when a concrete adaptive run did not succeed; return
    the trajectory. Inside a caller's own `jit` (concrete inputs closed over, traced
    outputs) nothing can be raised now: the failure is attached to the trajectory
    as diffrax's run-time error (`eqx.error_if`), as a traced run does."""
    succeeded = trajectory.run_stats.get("succeeded")
    if isinstance(succeeded, jax.core.Tracer):
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
        message = f"simulate failed: {result}. Pass throw=False to inspect the run."
    raise SimulationError(message, trajectory)
