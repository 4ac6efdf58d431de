"""Taylor coefficients of the solution of y' = f(t, y) through (t₀, y₀).

Write y(t₀ + τ) = Σₖ yₖ τᵏ. Then f(t, y(t)) = Σₖ fₖ τᵏ, and y' = f gives

    yₖ₊₁ = fₖ / (k + 1),

where fₖ depends on y₀..yₖ only. So the coefficients come one order at a time:
evaluate f once at (t₀, y₀) keeping every intermediate value (the order-0
coefficients of the whole graph), then for k = 1..p−1 give every operation its
k-th coefficient by its recurrence (`recurrences`) and append yₖ₊₁. Time itself is
the series t₀ + τ.

Two sweeps over the orders give the same numbers: `unroll=True` writes every
order out (static slices, one straight-line program XLA can fuse and schedule as
a whole), `unroll=False` runs a `fori_loop` over k (one loop body per operation,
a smaller program and a faster compile).

References: Jorba & Zou, Experimental Mathematics 14 (2005), §2; Hairer,
Nørsett & Wanner, "Solving ODEs I", §I.8; Moore, "Interval Analysis" (1966).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from .graph import Graph, lower
from .recurrences import with_coefficient


def lower_vector_field(
    vector_field: Callable, t0: Any, y0: jax.Array, args: Any
) -> tuple[Graph, list]:
    """The graph of `vector_field(t, y, args)` and the leaves of `args`."""
    leaves, treedef = jax.tree_util.tree_flatten(args)

    def flat(t, y, *arg_leaves):
        return vector_field(t, y, jax.tree_util.tree_unflatten(treedef, arg_leaves))

    closed = jax.make_jaxpr(flat)(t0, y0, *leaves)
    out_aval = closed.out_avals[0] if len(closed.out_avals) == 1 else None
    if out_aval is None or out_aval.shape != jnp.shape(y0):
        raise TypeError(
            "lagjax.Taylor: vector_field(t, y, args) must return one array shaped "
            f"like y {jnp.shape(y0)}, got {closed.out_avals}"
        )
    return lower(closed), leaves


def _order_zero(graph: Graph, inputs: list) -> dict[int, Any]:
    values = dict(graph.constants)
    values.update(zip(graph.inputs, inputs))
    for op in graph.ops:
        values.update(zip(op.outs, op.rule.zero(*(values[i] for i in op.ins))))
    return values


def _sweep(graph: Graph, values: dict, series: dict, k: Any) -> dict:
    """Order k of every series operation, then yₖ₊₁."""
    series = dict(series)
    for op in graph.ops:
        if op.outs[0] not in graph.series:
            continue
        inputs = tuple(series[i] if i in graph.series else values[i] for i in op.ins)
        outputs = tuple(series[o] for o in op.outs)
        new = op.rule.coefficient(k, inputs, outputs)
        for o, c in zip(op.outs, new):
            series[o] = with_coefficient(series[o], k, c)
    y = graph.inputs[1]
    if graph.output in graph.series:
        series[y] = with_coefficient(
            series[y], k + 1, series[graph.output][k] / (k + 1)
        )
    return series


def graph_coefficients(
    graph: Graph,
    t0: Any,
    y0: jax.Array,
    leaves: list,
    order: int,
    *,
    unroll: bool = True,
) -> jax.Array:
    """y₀..y_order, shape (order + 1, *y0.shape), from a lowered graph."""
    order + 1
    t0 = jnp.asarray(t0, dtype=y0.dtype)
    values = _order_zero(graph, [t0, y0, *leaves])
    series = {}
    for i in graph.series:
        if i in values:
            start = jnp.asarray(values[i], dtype=graph.avals[i].dtype)
            series[i] = [start] + [jnp.zeros_like(start)] * order
    t, y = graph.inputs[:2]
    if t in series:
        series[t] = with_coefficient(series[t], 1, jnp.ones_like(t0))
    f0 = jnp.asarray(values[graph.output], y0.dtype)
    series[y] = with_coefficient(series[y], 1, f0)
    if unroll:
        for k in range(1, order):
            series = _sweep(graph, values, series, k)
            # Stop XLA from fusing (and recomputing) one order's values into
            # every later order's kernels.
            series = jax.lax.optimization_barrier(series)
        return jnp.stack(series[y])
    arrays = {i: jnp.stack(s) for i, s in series.items()}
    arrays = jax.lax.fori_loop(
        1, max(order, 1), lambda k, s: _sweep(graph, values, s, k), arrays
    )
    return arrays[y]


def taylor_coefficients(
    vector_field: Callable,
    t0: Any,
    y0: jax.Array,
    args: Any = None,
    *,
    order: int,
    unroll: bool = True,
) -> jax.Array:
    """The Taylor coefficients y₀..y_order of the solution of
    y' = vector_field(t, y, args) through (t0, y0): shape (order + 1, *y0.shape).

    y0 is a flat float array. Raises `NotImplementedError` naming the first
    primitive of the vector field that has no Taylor rule.
    """
    y0 = jnp.asarray(y0)
    graph, leaves = lower_vector_field(vector_field, t0, y0, args)
    return graph_coefficients(graph, t0, y0, leaves, order, unroll=unroll)
