"""A batch of Taylor runs as one call: `lj.sweep`'s route for `lj.Taylor`.

`run_taylor_batch` runs `simulate(system, y0, ..., solver=taylor)` for every
member of a batch — initial states `y0s` and, optionally, parameters
`args_batch`, each with a leading batch axis — and returns one `Trajectory`
with that leading axis (as `jax.vmap` of `simulate` does). It is `jax.vmap` of
the single run: on the heyoka route the whole batch reaches heyoka's batch mode
in one `jax.pure_callback` (`lagjax.taylor.heyoka_callback`: blocks of the SIMD
width, every member with its own steps, events and outcome); on the JAX route
it is the vmapped JAX integrator.

References: F. Biscani & D. Izzo, MNRAS 504 (2021) 2614 (heyoka's batch mode);
the JAX documentation, `jax.vmap` and "External callbacks".
"""

from __future__ import annotations

from typing import Any

import jax

from lagjax._integrate.taylor_run import run_taylor
from lagjax.taylor.solver import Taylor
from lagjax.trajectory import Trajectory


def run_taylor_batch(
    system: Any, y0s: Any, args_batch: Any, t0: Any, t1: Any, ts: Any,
    solver: Taylor, rtol: float, atol: float, max_steps: int | None, throw: bool,
    *, args: Any = None, event: Any = None,
) -> Trajectory:  # fmt: skip
    """`simulate` with `solver` for every member of (`y0s`, `args_batch`); None
    for `args_batch` shares `args` across the batch. A failed member raises (with
    `throw`) or is told by its own `result`."""
    if not isinstance(solver, Taylor):
        raise TypeError(
            f"run_taylor_batch runs lj.Taylor solvers; got {type(solver).__name__}"
        )

    def member(y0: Any, member_args: Any) -> Trajectory:
        return run_taylor(
            system, y0, t0, t1, None, solver, ts,
            args if args_batch is None else member_args, rtol, atol, max_steps,
            throw, event=event,
        )  # fmt: skip

    batched_args = None if args_batch is None else 0
    return jax.vmap(member, in_axes=(0, batched_args))(y0s, args_batch)
