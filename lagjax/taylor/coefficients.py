"""Taylor coefficients of the solution of y' = f(t, y) through (t₀, y₀).

Write y(t₀ + τ) = Σₖ yₖ τᵏ. Then f(t, y(t)) = Σₖ fₖ τᵏ, and y' = f gives

    yₖ₊₁ = fₖ / (k + 1),

where fₖ depends on y₀..yₖ only. So the coefficients come one order at a time:
evaluate f once at (t₀, y₀) keeping every intermediate value (the order-0
coefficients of the whole graph), then for k = 1..p−1 give every operation its
k-th coefficient by its recurrence (`recurrences`) and append yₖ₊₁. Time itself is
the series t₀ + τ.

Three sweeps over the orders give the same numbers: `unroll=True` writes every
order out (static slices, one straight-line program; XLA's CPU fusion then
recomputes shared values in every consumer: 14 000 multiplications per step of
the double pendulum's batch for ~3 000 in the recurrences, and a minute to
compile), `unroll=False` runs a loop over k: for a scalar graph, of one
trajectory or of a batch, the tape (`tape`), else one series array per value.
(Until the tape's fifth-session form, one trajectory ran each order as one
matrix product of the graph's linear map; the tape took 0.62–0.67× its time on
the double pendulum and 0.27–0.31× on the n-link chain's n = 2.)

A batch (`batched_leaves`) carries the members on the last axis of every value:
in a scalar graph each operation is then one vector operation over them.

References: Jorba & Zou, Experimental Mathematics 14 (2005), §2; Hairer,
Nørsett & Wanner, "Solving ODEs I", §I.8; Moore, "Interval Analysis" (1966).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from lagjax._linalg.marked_solves import marking_solves
from lagjax._linalg.scalarize import as_object_array, objects_from_scalars, scalarize

from .graph import lower
from .graph_values import Graph
from .recurrences import with_coefficient
from .tape import supports, tape_coefficients


def lower_vector_field(
    vector_field: Callable, t0: Any, y0: jax.Array, args: Any, *, scalar: bool = False
) -> tuple[Graph, list]:
    """The graph of `vector_field(t, y, args)` and the leaves of `args`.

    `scalar=True` asks for a scalar graph (every value a scalar, the small arrays
    of f re-expressed element by element by `lagjax._linalg.scalarize`): in a
    batch each operation is then one vector operation over the members. When f
    cannot be scalarized the usual graph is returned (`graph.scalar` says which).
    """
    leaves, treedef = jax.tree_util.tree_flatten(args)

    def flat(t, y, *arg_leaves):
        return vector_field(t, y, jax.tree_util.tree_unflatten(treedef, arg_leaves))

    with marking_solves():  # a mass-matrix solve as one operation with its rule
        closed = jax.make_jaxpr(flat)(t0, y0, *leaves)
        twin = scalarize(flat, t0, y0, *leaves, branches=True) if scalar else None
    out_aval = closed.out_avals[0] if len(closed.out_avals) == 1 else None
    if out_aval is None or out_aval.shape != jnp.shape(y0):
        raise TypeError(
            "lagjax.Taylor: vector_field(t, y, args) must return one array shaped "
            f"like y {jnp.shape(y0)}, got {closed.out_avals}"
        )
    if twin is None:
        return lower(closed), leaves
    n, shapes = y0.shape[0], [jnp.shape(leaf) for leaf in leaves]
    dtype = out_aval.dtype

    def scalar_field(t, *scalars):
        ys, rest = objects_from_scalars(scalars[:n]), scalars[n:]
        arrays, start = [], 0
        for shape in shapes:
            size = math.prod(shape)
            arrays.append(
                objects_from_scalars(rest[start : start + size]).reshape(shape)
            )
            start += size
        rates = twin(as_object_array(t), ys, *arrays)
        return tuple(jnp.asarray(rate, dtype) for rate in rates)

    elements = [x for leaf in leaves for x in jnp.ravel(jnp.asarray(leaf))]
    scalar_jaxpr = jax.make_jaxpr(scalar_field)(t0, *y0, *elements)
    return lower(scalar_jaxpr, state_size=n), leaves


def _graph_inputs(graph: Graph, t0, y0, leaves, batched_leaves) -> tuple[list, list]:
    """The graph's input values and batch flags: the state whole or by element,
    the args' leaves whole or by element (a batched leaf's batch axis is last)."""
    if not graph.scalar:
        return [t0, y0, *leaves], [True, True, *batched_leaves]
    values, flags = [t0, *y0], [True] * (1 + y0.shape[0])
    for leaf, batched in zip(leaves, batched_leaves):
        leaf = jnp.asarray(leaf)
        rows = leaf.reshape((-1, leaf.shape[-1]) if batched else (-1,))
        values.extend(rows)
        flags.extend([batched] * rows.shape[0])
    return values, flags


def batched_values(graph: Graph, batched_inputs: tuple[bool, ...]) -> frozenset:
    """The values that carry the batch axis: the batched inputs and everything
    computed from them."""
    batched = {i for i, b in zip(graph.inputs, batched_inputs) if b}
    for op in graph.ops:
        if batched.intersection(op.ins):
            batched.update(op.outs)
    return frozenset(batched)


class _Batch(NamedTuple):
    """Which values carry the batch (last) axis, of how many members, and whether
    every value is a scalar per member (then each operation applies to the
    (B,)-vectors directly: elementwise primitives need equal shapes only)."""

    values: frozenset
    members: int
    scalar: bool


def _apply(
    fn: Callable, op: Any, batch: _Batch | None, inputs: tuple, *outputs: tuple
) -> tuple:
    """`fn(*inputs)`, or `fn(inputs, outputs)`, for one operation; in a batch,
    mapped over the trailing (minor) axis, so each elementary operation is one
    vector operation over the members (the order axis, where there is one, stays
    in front). The outputs of an operation with a batched input are batched."""
    if batch is None or not batch.values.intersection(op.ins):
        return fn(inputs, *outputs) if outputs else fn(*inputs)
    flags = [i in batch.values for i in op.ins]
    if batch.scalar:
        inputs = tuple(
            x if b else jnp.broadcast_to(x, (batch.members,))
            for x, b in zip(inputs, flags)
        )
        return fn(inputs, *outputs) if outputs else fn(*inputs)
    in_axes = tuple(-1 if b else None for b in flags)
    if outputs:
        return jax.vmap(fn, in_axes=(in_axes, -1), out_axes=-1)(inputs, *outputs)
    return jax.vmap(fn, in_axes=in_axes, out_axes=-1)(*inputs)


def _order_zero(graph: Graph, inputs: list, batch: _Batch | None) -> dict[int, Any]:
    values = dict(graph.constants)
    values.update(zip(graph.inputs, inputs))
    for op in graph.ops:
        ins = tuple(values[i] for i in op.ins)
        values.update(zip(op.outs, _apply(op.rule.zero, op, batch, ins)))
    return values


def _sweep(
    graph: Graph, values: dict, series: dict, k: Any, batch: _Batch | None
) -> dict:
    """Order k of every series operation, then yₖ₊₁."""
    series = dict(series)
    for op in graph.ops:
        if op.outs[0] not in graph.series:
            continue
        inputs = tuple(series[i] if i in graph.series else values[i] for i in op.ins)
        outputs = tuple(series[o] for o in op.outs)
        new = _apply(
            lambda ins, outs, op=op: op.rule.coefficient(k, ins, outs),
            op,
            batch,
            inputs,
            outputs,
        )
        if isinstance(k, int):
            # Written out: each operation's coefficient is materialised once.
            # XLA's CPU fusion would otherwise inline (recompute) it into every
            # consumer: 7x the multiplications of the recurrences, measured.
            new = jax.lax.optimization_barrier(tuple(new))
        for o, c in zip(op.outs, new):
            series[o] = with_coefficient(series[o], k, c)
    for y, rate in zip(graph.state, graph.outputs):
        if rate in graph.series:  # else constant in time: nothing above order 1
            value = jnp.broadcast_to(series[rate][k], series[y][0].shape)
            series[y] = with_coefficient(series[y], k + 1, value / (k + 1))
    return series


def graph_coefficients(
    graph: Graph,
    t0: Any,
    y0: jax.Array,
    leaves: list,
    order: int,
    *,
    unroll: bool = True,
    batched_leaves: tuple[bool, ...] | None = None,
    tape: jax.Array | None = None,
) -> Any:
    """y₀..y_order, shape (order + 1, *y0.shape), from a lowered graph.

    With `batched_leaves` (one flag per leaf of args), the run is a batch: t0 has
    shape (B,), y0 shape (n, B), a batched leaf a trailing axis B; the result has
    shape (order + 1, n, B). With `tape` (a loop's carried buffer, `tape.tape_shape`;
    only where the tape runs: `unroll=False` and `tape.supports(graph)`), the
    result is (coefficients, tape).
    """
    y0 = jnp.asarray(y0)
    t0 = jnp.asarray(t0, dtype=y0.dtype)
    inputs, flags = _graph_inputs(
        graph, t0, y0, leaves, batched_leaves or (False,) * len(leaves)
    )
    batch = None
    if batched_leaves is not None:
        chosen = batched_values(graph, tuple(flags))
        batch = _Batch(chosen, y0.shape[-1], graph.scalar)
    values = _order_zero(graph, inputs, batch)
    if not unroll and supports(graph):
        shape = () if batch is None else (batch.members,)
        return tape_coefficients(graph, values, order, shape, y0.dtype, tape)
    if tape is not None:
        raise ValueError(
            "lagjax.taylor: a tape was given for a graph the tape cannot run"
        )
    series = {}
    for i in graph.series:
        if i in values:
            start = jnp.asarray(values[i], dtype=graph.avals[i].dtype)
            series[i] = [start] + [jnp.zeros_like(start)] * order
    t = graph.inputs[0]
    if t in series:
        series[t] = with_coefficient(series[t], 1, jnp.ones_like(t0))
    for y, rate in zip(graph.state, graph.outputs):
        shape = series[y][0].shape
        f0 = jnp.broadcast_to(jnp.asarray(values[rate], y0.dtype), shape)
        series[y] = with_coefficient(series[y], 1, f0)

    def state(series: dict) -> jax.Array:
        rows = [jnp.stack(series[y]) for y in graph.state]
        return rows[0] if not graph.scalar else jnp.stack(rows, axis=1)

    if unroll:
        for k in range(1, order):
            series = _sweep(graph, values, series, k, batch)
            # Stop XLA from fusing (and recomputing) one order's values into
            # every later order's kernels.
            series = jax.lax.optimization_barrier(series)
        return state(series)
    arrays = {i: jnp.stack(s) for i, s in series.items()}
    arrays = jax.lax.fori_loop(
        1, max(order, 1), lambda k, s: _sweep(graph, values, s, k, batch), arrays
    )
    return state({y: arrays[y] for y in graph.state})


def taylor_coefficients(
    vector_field: Callable,
    t0: Any,
    y0: jax.Array,
    args: Any = None,
    *,
    order: int,
    unroll: bool = True,
    scalar: bool = False,
) -> jax.Array:
    """The Taylor coefficients y₀..y_order of the solution of
    y' = vector_field(t, y, args) through (t0, y0): shape (order + 1, *y0.shape).

    y0 is a flat float array. `scalar=True` lowers f to a scalar graph where it
    can (`lower_vector_field`); with `unroll=False` its orders are then computed
    on the tape (`tape`). Raises `NotImplementedError` naming the first primitive of
    the vector field that has no Taylor rule.
    """
    y0 = jnp.asarray(y0)
    graph, leaves = lower_vector_field(vector_field, t0, y0, args, scalar=scalar)
    return graph_coefficients(graph, t0, y0, leaves, order, unroll=unroll)
