"""`simulate` with `lj.Taylor`: Taylor-series integration of a system's derived
equations, by JAX or by heyoka.

The system's rates in the caller's convention (`AbstractSystem.state_rate`: (q̇, q̈)
for a Lagrangian, Hamilton's equations for a Hamiltonian) on the flat state
y = (q, q̇) or (q, p) are the vector field; its jaxpr of elementary operations is
what both routes work from:

- `backend="jax"` (`lagjax.taylor.taylor_integrate`): the Taylor coefficients by
  the recurrences of each primitive, order and step from the tolerance, the saves
  from the step polynomial; under `jit`, `vmap` and `grad`. `jax.vmap` of the run
  is the batch-native loop (`lagjax.taylor.vmap_rule`: one order, a step per
  member, the batch on the minor axis), not the batched one-trajectory loop.
- `backend="heyoka"` (`lagjax.taylor.heyoka_backend`): the jaxpr translated into
  heyoka's expressions (the parameters as heyoka parameters, so new `args` do not
  recompile) and integrated by heyoka's LLVM-compiled Taylor method; concrete
  values only (a traced call is refused by name), the fastest on one CPU.

The tolerances are the Taylor object's when it sets them, else `simulate`'s.
References: Jorba & Zou, *Experimental Mathematics* 14 (2005); Biscani & Izzo,
*MNRAS* 504 (2021).
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer
from jax.flatten_util import ravel_pytree

from lagjax._core.precision import cast_floats, working_dtype
from lagjax._core.system import AbstractSystem
from lagjax._integrate.checks.inputs import check_simulate_inputs
from lagjax._integrate.checks.late_failure import SimulationError, raise_if_failed
from lagjax._integrate.checks.taylor_overflow import (
    TRACED_MESSAGE,
    last_finite_state,
    overflow_message,
)
from lagjax._integrate.taylor_heyoka import (
    BAD_TIMES_MESSAGE,
    heyoka_member,
    heyoka_runner,
    member_trajectory,
)
from lagjax._integrate.taylor_polynomial_run import simulate_taylor_polynomials
from lagjax.taylor.integrate import RESULTS as TAYLOR_RESULTS
from lagjax.taylor.integrate import resolve_order
from lagjax.taylor.solver import Taylor
from lagjax.taylor.vmap_rule import taylor_integrate_vmappable
from lagjax.trajectory import Trajectory


def run_taylor(
    system: Any, y0: Any, t0: Any, t1: Any, dt: Any, solver: Taylor, ts: Any,
    args: Any, rtol: float, atol: float, max_steps: int | None, throw: bool,
    event: Any = None, **options: Any,
) -> Trajectory:  # fmt: skip
    """`simulate` for a `Taylor` solver: the checks, the run, the verdict."""
    dense = bool(options.pop("dense", False))
    refuse_taylor_options(dt=dt, dense=dense and solver.backend == "heyoka", **options)
    if t1 is None and isinstance(system, AbstractSystem):
        t1 = system.default_span()[0]
    y0 = check_simulate_inputs(system, y0, t0, t1, None, None, ts, args, max_steps)
    system, args = system.resolve(args)
    if system.keeps_constraints():
        raise ValueError(
            "lj.Taylor integrates the equations of motion and does not keep "
            "constraints; use Rattle (holonomic) or a diffrax solver, which simulate "
            "projects onto the constraints"
        )
    dtype = working_dtype(y0)
    system.check_start(y0, t0, args, dtype)
    if solver.backend == "heyoka" and not _traced(y0, args, ts, t0, t1):
        # NumPy in, NumPy out: no eager JAX dispatch on the fast CPU route
        y0 = jax.tree_util.tree_map(lambda x: np.asarray(x, dtype=dtype), tuple(y0))
        save_ts = None if ts is None else np.asarray(ts, dtype=dtype)
    else:
        y0, args = cast_floats(y0, dtype), cast_floats(args, dtype)
        save_ts = None if ts is None else jnp.asarray(ts, dtype=dtype)
    if solver.backend == "jax" and (event is not None or dense):
        # events and dense output from the step polynomials (taylor_polynomial_run)
        trajectory = simulate_taylor_polynomials(
            system, flat_vector_field(system, y0), t0, t1, save_ts, args, solver,
            rtol=rtol, atol=atol, max_steps=max_steps, event=event, dense=dense,
        )  # fmt: skip
    else:
        trajectory = simulate_taylor(
            system, y0, t0, t1, save_ts, args, solver,
            rtol=rtol, atol=atol, max_steps=max_steps, event=event,
        )  # fmt: skip
    if throw:
        # the tolerances the run used: the solver's own when it has them
        rtol = rtol if solver.rtol is None else solver.rtol
        atol = atol if solver.atol is None else solver.atol
        _raise_if_overflowed(
            trajectory, system, (t0, y0), resolve_order(rtol, atol, solver.order)
        )
        trajectory = _verdict(trajectory, rtol)
    return trajectory


def _raise_if_overflowed(
    trajectory: Trajectory, system: AbstractSystem, start: tuple, order: int
) -> None:
    """A concrete run that went non-finite because its Taylor series overflowed,
    raised with its own message (`checks.taylor_overflow`); the series is taken
    at the last finite save, or at the `start` (t0, y0) when none is. A run that
    ended finite costs two lookups here, nothing more."""
    if _traced(trajectory.ts, trajectory.ys):
        return
    finite = bool(np.all(np.asarray(trajectory.run_stats.get("finite", True))))
    if finite and not bool(np.any(trajectory.result == diffrax.RESULTS.nonfinite)):
        return
    t0, y0 = start
    field, flat0, _ = flat_vector_field(system, y0)
    t, y = last_finite_state(trajectory) or (t0, flat0)
    message = overflow_message(field, t, y, trajectory.args, order)
    if message is not None:
        raise SimulationError(message, trajectory)


def _traced(*trees: Any) -> bool:
    leaves = jax.tree_util.tree_leaves(trees)
    return any(isinstance(x, Tracer) for x in leaves)


def _verdict(trajectory: Trajectory, rtol: float) -> Trajectory:
    """A failed run raised: now for concrete values, at run time (`eqx.error_if`)
    for traced ones. Ending at an event is no failure."""
    stats = trajectory.run_stats
    if _traced(trajectory.ts, trajectory.ys):
        if "succeeded" in stats:  # heyoka: a code per member
            failed = ~stats["succeeded"]
            trajectory = eqx.error_if(trajectory, stats["bad_times"], BAD_TIMES_MESSAGE)
        else:
            failed = trajectory.result != diffrax.RESULTS.successful
        if "finite" in stats:  # the JAX route: non-finite told apart
            trajectory = eqx.error_if(trajectory, ~stats["finite"], TRACED_MESSAGE)
        return eqx.error_if(
            trajectory, failed,
            "lj.Taylor did not reach t1: raise max_steps, or see traj.result "
            "with throw=False",
        )  # fmt: skip
    succeeded = stats.get("succeeded")
    if succeeded is None:
        succeeded = trajectory.result == diffrax.RESULTS.successful
    if not bool(np.all(succeeded)):
        raise_if_failed(trajectory, stats["max_steps"], rtol)
    return trajectory


def refuse_taylor_options(**options: Any) -> None:
    """Options `simulate` has that a Taylor run does not support, refused by name."""
    given = [name for name, value in options.items() if value not in (None, False)]
    if given:
        raise ValueError(
            f"lj.Taylor does not support {', '.join(given)} yet: save at given "
            "times with ts=... (filled from the step polynomials), dense output "
            "with lj.Taylor(backend='jax'), or use a diffrax solver "
            "(diffrax.Dopri8()) for step-size controllers and custom adjoints"
        )


class FlatVectorField(eqx.Module):
    """y' = field(t, y, args) on the flat state y = ravel((q, second)).

    A Module, not a closure: two fields of equal systems and state layouts compare
    equal and hash alike, so the heyoka backend's translation cache (keyed by the
    function) and JAX's compilation caches are hit on every later call.
    """

    system: AbstractSystem
    layout: tuple = eqx.field(static=True)  # (treedef, shapes, dtypes) of (q, second)

    def unravel(self, y: jax.Array) -> Any:
        treedef, shapes, _ = self.layout
        sizes = [int(np.prod(shape)) for shape in shapes]
        pieces = jnp.split(y, np.cumsum(sizes)[:-1])
        leaves = [piece.reshape(shape) for piece, shape in zip(pieces, shapes)]
        return jax.tree_util.tree_unflatten(treedef, leaves)

    def __call__(self, t: Any, y: jax.Array, args: Any) -> jax.Array:
        q, second = self.unravel(y)
        rate = self.system.state_rate(q, second, t, args)
        return ravel_pytree(rate)[0].astype(y.dtype)


_FIELDS: OrderedDict[Any, FlatVectorField] = OrderedDict()


def _one_field_per_system(system: AbstractSystem, layout: tuple) -> FlatVectorField:
    """The same field object for the same system and layout: the caches keyed by
    it (heyoka's translations) then match by identity, not by comparing systems
    leaf by leaf (milliseconds per call)."""
    try:
        key = (system, layout)
        field = _FIELDS.get(key)
    except TypeError:  # a system with array leaves does not hash
        return FlatVectorField(system, layout)
    if field is None:
        field = _FIELDS[key] = FlatVectorField(system, layout)
        while len(_FIELDS) > 64:
            _FIELDS.popitem(last=False)
    return field


def _dtype_name(x: Any) -> str:
    """The dtype's name of an array, a tracer or a Python number (NumPy 2.4
    deprecates `np.result_type` of an array-like)."""
    if isinstance(x, (np.ndarray, np.generic, jax.Array)):
        return np.dtype(x.dtype).name
    return np.result_type(x).name


def flat_vector_field(system: AbstractSystem, y0: Any):
    """`(field, flat0, unravel)` for the state `y0` of `system`."""
    leaves, treedef = jax.tree_util.tree_flatten(tuple(y0))
    layout = (
        treedef,
        tuple(np.shape(x) for x in leaves),
        tuple(_dtype_name(x) for x in leaves),
    )
    field = _one_field_per_system(system, layout)
    if all(isinstance(x, np.ndarray) for x in leaves):  # heyoka's route: no JAX op
        flat0 = np.concatenate([np.ravel(x) for x in leaves])
    else:
        flat0 = ravel_pytree(tuple(y0))[0]
    return field, flat0, field.unravel


def simulate_taylor(
    system: AbstractSystem,
    y0: Any,
    t0: Any,
    t1: Any,
    ts: Any,
    args: Any,
    solver: Taylor,
    *,
    rtol: float,
    atol: float,
    max_steps: int | None,
    event: Any = None,
) -> Trajectory:
    """The run of `simulate(system, y0, solver=lj.Taylor(...))` (module docstring);
    failures are reported in `result` (the caller raises)."""
    field, flat0, unravel = flat_vector_field(system, y0)
    rtol = rtol if solver.rtol is None else solver.rtol
    atol = atol if solver.atol is None else solver.atol
    steps = max_steps or solver.max_steps
    if solver.backend == "heyoka":
        runner, structure = heyoka_runner(
            field, flat0.shape[0], args, solver, rtol, atol, steps, event,
            final_only=ts is None,
        )  # fmt: skip
        rows = heyoka_member(runner, flat0, args, t0, t1, ts)
        return member_trajectory(field, rows, structure, steps, system, args)
    solution = taylor_integrate_vmappable(
        field, flat0, t0, t1, ts=ts, args=args, rtol=rtol, atol=atol,
        order=solver.order, max_steps=steps, forward_mode=solver.forward_mode,
        tile=solver.tile,
    )  # fmt: skip
    stats: dict[str, Any] = {
        "num_steps": solution.num_steps,
        "num_accepted_steps": solution.num_steps,
        "num_rejected_steps": 0 * solution.num_steps,
        "max_steps": steps,
        "finite": jnp.all(jnp.isfinite(solution.ys)),
    }
    return Trajectory(
        ts=solution.ts, ys=jax.vmap(unravel)(solution.ys), system=system, args=args,
        run_stats=stats, result=as_diffrax_result(solution.result),
        solver_name=f"Taylor[{solver.backend}]",
    )  # fmt: skip


def as_diffrax_result(result: Any) -> Any:
    """The Taylor integrator's codes are diffrax's plus `non_finite`."""
    finite = result != TAYLOR_RESULTS.non_finite
    return diffrax.RESULTS.where(
        finite,
        diffrax.RESULTS.where(
            result == TAYLOR_RESULTS.successful,
            diffrax.RESULTS.successful,
            diffrax.RESULTS.max_steps_reached,
        ),
        diffrax.RESULTS.nonfinite,  # pyright: ignore[reportArgumentType]
    )
