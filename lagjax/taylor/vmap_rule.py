"""One Taylor run that `jax.vmap` turns into the batch-native loop.

`jax.vmap` of the one-trajectory loop (`integrate.taylor_integrate`) batches a
`while_loop` whose members take different numbers of steps: every member waits
for the slowest, every update of the carry is guarded by a select, and the batch
sits on the major axis (×1024 double pendulums to t = 10 at 1e-12: 13.3 s
against 598 ms for `batch.taylor_integrate_batch`, loaded machine). Users write
`jax.vmap(simulate)`, so `taylor_integrate_vmappable` gives the one-trajectory
run a batching rule of its own (`jax.custom_batching.custom_vmap`): under
`vmap` it calls the batch-native loop, which takes the batch of y0, of the leaves
of args (and of the vector field, a system with array fields), of t0, t1 and of
the save times. Both loops take the same steps by the same rule, so a member's
result is its own run's to rounding.

Differentiation goes around the batching rule: `custom_vmap` has no reverse
mode, so it sits under the derivative `taylor_integrate` has always had — a
`jax.custom_vjp` whose rule is the VJP of the plain run (the checkpointed loop,
for `jax.grad`), or with `forward_mode=True` a `jax.custom_jvp` whose rule is
its JVP (the plain loop, for `jax.jvp`). A differentiated `vmap` therefore
batches that rule as before: the fast loop is for the values, the
one-trajectory loop for the derivatives. Batched
tolerances, which the batch loop takes as scalars, are run by `vmap` of the
plain run.

References: the JAX documentation, `jax.custom_batching.custom_vmap` and
`jax.custom_jvp`; Biscani & Izzo, MNRAS 504 (2021), §5 (batch mode).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.core import Tracer

from .batch import taylor_integrate_batch
from .integrate import TaylorSolution, resolve_order, taylor_integrate


def _differentiated_as(one: Callable, batchable: Callable, forward_mode: bool):
    """`batchable` with the derivatives of `one`: its JVP for forward mode (the
    plain loop), its VJP for reverse mode (the checkpointed loop, a `custom_vjp`
    that a JVP, even one later transposed, cannot enter)."""
    if forward_mode:
        run = jax.custom_jvp(batchable)
        run.defjvp(lambda primals, tangents: jax.jvp(one, primals, tangents))
        return run
    run = jax.custom_vjp(batchable)
    run.defvjp(lambda *primals: jax.vjp(one, *primals), lambda pull, ct: pull(ct))
    return run


def _closure_converted(vector_field: Callable, t0: Any, y0: Any, args: Any) -> Callable:
    """`vector_field`, or, when it closes over traced values (`jax.vmap(lambda w:
    simulate(Lagrangian(lambda q, v: ... w ...)))`), the same function with the
    values it closes over as array leaves: the batching rule and the derivative
    rules then receive them as inputs (a closed-over tracer cannot enter them)."""
    converted = eqx.filter_closure_convert(vector_field, t0, y0, args)
    if any(isinstance(leaf, Tracer) for leaf in jax.tree_util.tree_leaves(converted)):
        return converted
    return vector_field


class _Rejoined(eqx.Module):
    """The vector field rebuilt from its array leaves: `dynamic` holds the
    arrays of (vector_field, args, rtol, atol), `static` the rest, so the arrays
    of a system travel as inputs the batching rule can see batched."""

    static: Any

    def __call__(self, t: Any, y: jax.Array, dynamic: Any) -> jax.Array:
        vector_field, args, _, _ = eqx.combine(dynamic, self.static)
        return vector_field(t, y, args)


def taylor_integrate_vmappable(
    vector_field: Callable,
    y0: Any,
    t0: Any,
    t1: Any,
    *,
    ts: Any = None,
    args: Any = None,
    rtol: Any = 1e-15,
    atol: Any = 1e-15,
    order: int | None = None,
    max_steps: int = 1_000_000,
    forward_mode: bool = False,
    tile: int | None = None,
) -> TaylorSolution:
    """`taylor_integrate` (same arguments, same result) whose `jax.vmap` runs
    `taylor_integrate_batch` with `tile` members per loop (None: from the
    platform); derivatives are `taylor_integrate`'s (module docstring)."""
    p = resolve_order(rtol, atol, order)
    y0 = jnp.asarray(y0)
    t0, t1 = jnp.asarray(t0, y0.dtype), jnp.asarray(t1, y0.dtype)
    save_ts = jnp.atleast_1d(jnp.asarray(t1 if ts is None else ts, y0.dtype))
    vector_field = _closure_converted(vector_field, t0, y0, args)
    dynamic, static = eqx.partition((vector_field, args, rtol, atol), eqx.is_array)
    field = _Rejoined(static)

    def one(dynamic, y0, t0, t1, ts):
        _, _, rtol, atol = eqx.combine(dynamic, static)
        solution = taylor_integrate(
            field, y0, t0, t1, ts=ts, args=dynamic, rtol=rtol, atol=atol,
            order=p, max_steps=max_steps, forward_mode=forward_mode,
        )  # fmt: skip
        return solution.ys, solution.num_steps, solution.result

    @jax.custom_batching.custom_vmap
    def batchable(dynamic, y0, t0, t1, ts):
        return one(dynamic, y0, t0, t1, ts)

    @batchable.def_vmap
    def batch_rule(size, in_batched, dynamic, y0, t0, t1, ts):
        _, _, rtol_batched, atol_batched = in_batched[0]
        if rtol_batched or atol_batched:  # the batch loop takes scalar tolerances
            axes = jax.tree_util.tree_map(lambda b: 0 if b else None, in_batched)
            out = jax.vmap(one, in_axes=tuple(axes))(dynamic, y0, t0, t1, ts)
        else:
            _, _, rtol, atol = eqx.combine(dynamic, static)
            solution = taylor_integrate_batch(
                field, y0 if in_batched[1] else jnp.broadcast_to(y0, (size, *y0.shape)),
                t0, t1, ts=ts, args=dynamic,
                args_axis=jax.tree_util.tree_map(lambda b: 0 if b else None, in_batched[0]),
                rtol=rtol, atol=atol, order=p, max_steps=max_steps, tile=tile,
            )  # fmt: skip
            out = (solution.ys, solution.num_steps, solution.result)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    run = _differentiated_as(one, batchable, forward_mode)
    ys, num_steps, result = run(dynamic, y0, t0, t1, save_ts)
    return TaylorSolution(
        ts=save_ts, ys=ys, num_steps=num_steps, result=result, order=p
    )
