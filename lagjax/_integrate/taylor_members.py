"""A sweep's members on the JAX Taylor route's batch-native loop.

`jax.vmap` of `simulate(..., solver=lj.Taylor())` batches the one-trajectory
`while_loop`: every member waits for the slowest and every update is guarded by
a select (×1024 double pendulums to t = 10 at 1e-12: 13.3 s, loaded machine).
`lagjax.taylor.batch.taylor_integrate_batch` runs the batch as heyoka's batch
mode does — one order, a step size per member, the batch on the minor axis, one
loop per tile — 598 ms on the same case (heyoka's batch mode 446 ms in that
run). `lj.sweep` hands its chunks of members here when the solver is
`lj.Taylor(backend="jax")`; the result is what `jax.vmap(simulate)` returns: a
`Trajectory` with a leading member axis.

The batch loop is a forward computation: for gradients through a Taylor sweep,
vmap `simulate`, whose values come from the same batch loop and whose
derivatives from the one-trajectory loop (`lagjax.taylor.vmap_rule`).
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._core.precision import cast_floats, working_dtype
from lagjax._core.system import AbstractSystem
from lagjax._integrate.taylor_run import as_diffrax_result, flat_vector_field
from lagjax.taylor.batch import taylor_integrate_batch
from lagjax.taylor.solver import Taylor
from lagjax.trajectory import Trajectory

# The options of `simulate` this route takes; any other asks for vmap of simulate.
_OPTIONS = frozenset({"t0", "t1", "ts", "solver", "rtol", "atol", "max_steps", "throw"})


def runs_on_taylor_batch(simulate_kwargs: dict[str, Any]) -> bool:
    """Whether a sweep with these `simulate` options runs on the batch loop."""
    solver = simulate_kwargs.get("solver")
    return (
        isinstance(solver, Taylor)
        and solver.backend == "jax"
        and set(simulate_kwargs) <= _OPTIONS
    )


def taylor_members(
    system: AbstractSystem, shared_args: Any, simulate_kwargs: dict[str, Any],
    members: tuple[Any, Any],
) -> Trajectory:  # fmt: skip
    """`jax.vmap(simulate)` over `members = (y0s, args_batch)` (args_batch None:
    every member takes `shared_args`) by the batch-native Taylor loop."""
    y0s, args_batch = members
    solver: Taylor = simulate_kwargs["solver"]
    t0 = simulate_kwargs.get("t0", 0.0)
    t1 = simulate_kwargs.get("t1")
    if t1 is None:
        t1 = system.default_span()[0]
    ts = simulate_kwargs.get("ts")
    rtol = solver.rtol if solver.rtol is not None else simulate_kwargs.get("rtol")
    atol = solver.atol if solver.atol is not None else simulate_kwargs.get("atol")
    rtol, atol = rtol or 1e-8, atol or 1e-8
    steps = simulate_kwargs.get("max_steps") or solver.max_steps
    one_y0 = jax.tree_util.tree_map(lambda leaf: leaf[0], y0s)
    dtype = working_dtype(one_y0)
    resolved, args = system.resolve(shared_args if args_batch is None else None)
    if args_batch is not None:
        args = args_batch
    y0s, args = cast_floats(y0s, dtype), cast_floats(args, dtype)
    field, _, unravel = flat_vector_field(resolved, one_y0)
    flat0s = jax.vmap(lambda y0: ravel_pytree(tuple(y0))[0])(y0s)
    solution = taylor_integrate_batch(
        field, flat0s, t0, t1, ts=ts, args=args,
        args_axis=None if args_batch is None else 0,
        rtol=rtol, atol=atol, order=solver.order, max_steps=steps, tile=solver.tile,
    )  # fmt: skip
    size = flat0s.shape[0]
    saved_ts = jnp.broadcast_to(solution.ts, (size, *jnp.shape(solution.ts)[-1:]))
    member_args = (
        args_batch if args_batch is not None
        else jax.tree_util.tree_map(lambda leaf: jnp.broadcast_to(leaf, (size, *jnp.shape(leaf))), args)
    )  # fmt: skip

    def trajectory(ts, flat_ys, num_steps, result, member_args):
        stats = {
            "num_steps": num_steps, "num_accepted_steps": num_steps,
            "num_rejected_steps": 0 * num_steps, "max_steps": steps,
            "finite": jnp.all(jnp.isfinite(flat_ys)),
        }  # fmt: skip
        return Trajectory(
            ts=ts, ys=jax.vmap(unravel)(flat_ys), system=resolved, args=member_args,
            run_stats=stats, result=as_diffrax_result(result),
            solver_name="Taylor[jax, batch]",
        )  # fmt: skip

    batch = jax.vmap(trajectory)(
        saved_ts, solution.ys, solution.num_steps, solution.result, member_args
    )
    if simulate_kwargs.get("throw", True):
        batch = eqx.error_if(
            batch, jnp.any(batch.result != diffrax.RESULTS.successful),
            "lj.Taylor did not reach t1 for some members of the sweep: raise "
            "max_steps, or pass throw=False and read traj.result per member",
        )  # fmt: skip
    return batch
