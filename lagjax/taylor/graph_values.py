"""The values and operations of a vector field's Taylor graph, and the builder
that records them while `graph.lower` walks the jaxpr.

Every value of the graph is an integer id with an abstract value (shape and
dtype); it is a *series* (it varies along the solution) or *fixed* within a step,
and a fixed value known at lowering is a constant. An operation (`Op`) applies
one Taylor rule (`recurrences`) to input ids and gives output ids. The builder
hands out ids, keeps the constants, and merges repeated operations on the same
inputs (common subexpressions) by a key of primitive, inputs and params.

References: the JAX documentation, "Writing custom Jaxpr interpreters in JAX".
"""

from __future__ import annotations

from collections import Counter
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import lagjax.taylor.recurrences as rec

from .graph_signs import Signs, default_params


class Op(NamedTuple):
    rule: rec.AbstractRule
    ins: tuple[int, ...]
    outs: tuple[int, ...]


class Graph(NamedTuple):
    """Operations in evaluation order; values are integer ids."""

    ops: tuple[Op, ...]
    series: frozenset[int]
    constants: dict[int, Any]
    avals: dict[int, Any]
    inputs: tuple[int, ...]  # t, the state, then the leaves of args
    state: tuple[int, ...]  # y, or its elements y₀..yₙ₋₁ in a scalar graph
    outputs: tuple[int, ...]  # dy/dt, or its elements in a scalar graph
    scalar: bool = False  # every value a scalar; args enter element by element

    def census(self) -> Counter:
        """How many series operations of each rule the graph evaluates."""
        return Counter(
            type(op.rule).__name__ for op in self.ops if op.outs[0] in self.series
        )


def is_float(aval: Any) -> bool:
    return jnp.issubdtype(aval.dtype, jnp.inexact)


def _plain(value: Any) -> Any:
    """NumPy scalars inside a primitive's params (`split`'s sizes are np.int64)
    as Python numbers: the params are a static field of the rule, and equinox
    warns of (and JAX would not hash) array leaves there."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, tuple) and not hasattr(value, "_fields"):
        return tuple(_plain(v) for v in value)
    return value


def primitive_params(eqn: Any) -> dict:
    return {name: _plain(value) for name, value in eqn.params.items()}


def frozen_params(params: dict) -> tuple | None:
    try:
        key = tuple(sorted(params.items()))
        hash(key)
        return key
    except TypeError:
        return None


def inner_jaxpr(eqn: Any) -> tuple[Any, list]:
    for name in ("jaxpr", "call_jaxpr", "fun_jaxpr"):
        inner = eqn.params.get(name)
        if inner is not None:
            if hasattr(inner, "consts"):
                return inner.jaxpr, list(inner.consts)
            return inner, []
    raise NotImplementedError(
        f"lagjax.Taylor: cannot enter the call primitive {eqn.primitive.name!r}"
    )


class Builder:
    """Ids, constants, operations and the merging of repeated ones, for `lower`."""

    def __init__(self) -> None:
        self.ops: list[Op] = []
        self.series: set[int] = set()
        self.constants: dict[int, Any] = {}
        self.avals: dict[int, Any] = {}
        self.seen: dict[Any, tuple[int, ...]] = {}
        self.signs = Signs(self)

    def new(self, aval: Any, series: bool) -> int:
        index = len(self.avals)
        self.avals[index] = aval
        if series:
            self.series.add(index)
        return index

    def constant(self, value: Any) -> int:
        value = jnp.asarray(value) if not hasattr(value, "aval") else value
        index = self.new(jax.typeof(value), series=False)
        self.constants[index] = value
        return index

    def emit(self, rule, ins, out_avals, series: bool, key=None) -> tuple[int, ...]:
        if key is not None and key in self.seen:
            return self.seen[key]
        outs = tuple(self.new(aval, series) for aval in out_avals)
        self.ops.append(Op(rule, tuple(ins), outs))
        if key is not None:
            self.seen[key] = outs
        return outs

    def constant_is(self, index: int, value: float) -> bool:
        """Whether value `index` is the scalar constant `value` (a literal, or
        one folded at lowering)."""
        const = self.constants.get(index)
        return (
            const is not None
            and np.shape(const) == ()
            and bool(np.asarray(const) == value)
        )

    def flags(self, ins) -> tuple[bool, ...]:
        return tuple(i in self.series for i in ins)

    def primitive(self, name: str, ins, aval) -> int:
        """One more series operation (used when rewriting x**n and x**2)."""
        prim = getattr(jax.lax, f"{name}_p")
        params = default_params(name)
        rule = (
            rec.Product(primitive=prim, params=params, series=(True, True))
            if name == "mul"
            else rec.Quotient(primitive=prim, params=params, series=self.flags(ins))
        )
        return self.emit(rule, ins, [aval], True, key=(name, tuple(ins), ()))[0]
