"""`simulate` with `lj.Taylor(backend="jax")` and an `event` or `dense=True`: what
the run reads off its step polynomials besides the saves.

- `event=diffrax.Event(cond_fn, direction=...)`, real-valued conditions
  `cond_fn(t, y, args)` with `y` in `y0`'s convention (as for every solver): each
  step samples them on its polynomial and the crossing is located on it to
  round-off (`lagjax.taylor.events`). As on heyoka's route
  (`lagjax._integrate.taylor_heyoka`): `result` is `RESULTS.event_occurred`,
  `stats["event_mask"]` says which condition fired, the saves after the event
  are t = inf, y = inf, and without `ts` the one save is the state at the event.
  `root_finder` is not needed (the polynomial is the solution).
- `dense=True`: every step's polynomial is kept (`lagjax.taylor.dense`) and
  `traj.evaluate(t)` is the state at any t of the run, in `y0`'s convention. The
  buffer has one row per allowed step: `max_steps` when `simulate` is given it,
  else at most `DENSE_ROWS` (diffrax's default; a longer run ends with
  `max_steps_reached` and the message names the remedy).

References: Biscani & Izzo, MNRAS 504 (2021), §4–5 (dense output and events of
the Taylor method); the diffrax documentation, `diffrax.Event`.
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax.taylor.dense import TaylorDense
from lagjax.taylor.events import StepEvent
from lagjax.taylor.integrate import RESULTS as TAYLOR_RESULTS
from lagjax.taylor.integrate import taylor_integrate
from lagjax.taylor.solver import Taylor
from lagjax.trajectory import Trajectory

# Rows of the dense buffer when simulate is not given max_steps (diffrax's
# default max_steps): each row holds a step's (p + 1) × n coefficients.
DENSE_ROWS = 4096


class ConditionOnFlatState(eqx.Module):
    """An event condition `fn(t, y, args)` fed the caller's state from the flat y."""

    fn: Any
    unravel: Any

    def __call__(self, t: Any, y: jax.Array, args: Any) -> jax.Array:
        return jnp.asarray(self.fn(t, self.unravel(y), args))


class DenseOnFlatState(eqx.Module):
    """The run's polynomials evaluated in the caller's convention (`Trajectory.evaluate`)."""

    dense: TaylorDense
    unravel: Any

    def evaluate(self, t: Any) -> tuple[Any, Any]:
        flat = self.dense.evaluate(t)
        return jax.vmap(self.unravel)(flat) if flat.ndim > 1 else self.unravel(flat)


def step_event(event: Any, field: Any, flat0: Any, t0: Any, args: Any) -> StepEvent:
    """`event` (a `diffrax.Event`) as conditions on the flat state, checked real."""
    if not isinstance(event, diffrax.Event):
        raise TypeError(
            f"event must be a diffrax.Event (diffrax.Event(cond_fn)), got "
            f"{type(event).__name__}"
        )
    functions = jax.tree_util.tree_leaves(event.cond_fn, is_leaf=callable)
    conditions = tuple(ConditionOnFlatState(fn, field.unravel) for fn in functions)
    for condition in conditions:
        out = jax.eval_shape(condition, jnp.asarray(t0, flat0.dtype), flat0, args)
        if out.shape != () or not jnp.issubdtype(out.dtype, jnp.floating):
            raise ValueError(
                "lj.Taylor locates an event where a real-valued condition crosses "
                f"zero (on the step's Taylor polynomial); this condition returns "
                f"{out.dtype}{list(out.shape)}. Return one float, e.g. "
                "`lambda t, y, args: y[0]` rather than `y[0] < 0`."
            )
    direction = event.direction
    if direction is None or isinstance(direction, bool):
        directions = [direction] * len(conditions)
    else:
        directions = jax.tree_util.tree_leaves(direction, is_leaf=lambda x: x is None)
    signs = tuple({None: 0, True: 1, False: -1}[d] for d in directions)
    return StepEvent(conditions, signs)


def simulate_taylor_polynomials(
    system: Any, fields: tuple, t0: Any, t1: Any, ts: Any, args: Any,
    solver: Taylor, *, rtol: float, atol: float, max_steps: int | None,
    event: Any, dense: bool,
) -> Trajectory:  # fmt: skip
    """The run of `simulate(system, y0, solver=lj.Taylor(), event=..., dense=...)`
    from `fields` = `taylor_run.flat_vector_field(system, y0)`; failures are
    reported in `result` (the caller raises)."""
    field, flat0, unravel = fields
    rtol = rtol if solver.rtol is None else solver.rtol
    atol = atol if solver.atol is None else solver.atol
    steps = max_steps or (
        min(solver.max_steps, DENSE_ROWS) if dense else solver.max_steps
    )
    watched = None if event is None else step_event(event, field, flat0, t0, args)
    solution = taylor_integrate(
        field, flat0, t0, t1, ts=ts, args=args, rtol=rtol, atol=atol,
        order=solver.order, max_steps=steps, forward_mode=solver.forward_mode,
        event=watched, dense=dense,
    )  # fmt: skip
    unused = jnp.isinf(solution.ts)[:, None]  # the saves after an event
    result = _as_diffrax_result(solution.result)
    stats: dict[str, Any] = {
        "num_steps": solution.num_steps,
        "num_accepted_steps": solution.num_steps,
        "num_rejected_steps": 0 * solution.num_steps,
        "max_steps": steps,
        "finite": jnp.all(jnp.isfinite(solution.ys) | unused),
        # as heyoka's route: an event is a success; no save times are refused here
        "succeeded": (result == diffrax.RESULTS.successful)
        | (result == diffrax.RESULTS.event_occurred),
        "bad_times": jnp.zeros((), bool),
    }
    if event is not None:
        structure = jax.tree_util.tree_structure(event.cond_fn, is_leaf=callable)
        fired = list(solution.event_mask)  # pyright: ignore[reportArgumentType]
        stats["event_mask"] = jax.tree_util.tree_unflatten(structure, fired)
    return Trajectory(
        ts=solution.ts, ys=jax.vmap(unravel)(solution.ys), system=system, args=args,
        run_stats=stats, result=result, solver_name=f"Taylor[{solver.backend}]",
        dense_output=None
        if solution.dense is None
        else DenseOnFlatState(solution.dense, unravel),
    )  # fmt: skip


def _as_diffrax_result(result: Any) -> Any:
    """The Taylor integrator's codes as diffrax's: its own `non_finite` is
    diffrax's `nonfinite`, the others are diffrax's by name."""
    where = diffrax.RESULTS.where
    mapped = diffrax.RESULTS.max_steps_reached
    for name in ("successful", "event_occurred"):
        mapped = where(
            result == getattr(TAYLOR_RESULTS, name),
            getattr(diffrax.RESULTS, name),
            mapped,  # pyright: ignore[reportArgumentType]
        )
    return where(
        result == TAYLOR_RESULTS.non_finite,
        diffrax.RESULTS.nonfinite,  # pyright: ignore[reportArgumentType]
        mapped,
    )
