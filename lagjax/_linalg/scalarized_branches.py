"""`lax.cond` and `lax.switch` in a scalarized function: the branches as scalar
functions of the operands' elements, in one `lax.switch`.

`scalarize` keeps a function as written when its jaxpr holds a primitive it does
not know; a branch is one such place, and the mass-matrix solve of a Lagrangian
with four or more coordinates has one (LDLᵀ, with a pivoted LU as the fallback
for an indefinite matrix, `lagjax._linalg.small_solves`). Where the caller asks
for branches, the `cond` equation is re-expressed on scalars instead: its
operands' elements go into a `lax.switch` whose branches take scalars and
return scalars. A branch that itself scalarizes is evaluated on scalars; any
other (the LU fallback, written as loops) is evaluated as written on the arrays
rebuilt from the scalars. Either way the result is the function's own, element
by element; only the program's form changes.

Opt-in (`scalarize(..., branches=True)`): the Taylor integrator lowers each branch
into its graph (`lagjax.taylor.graph`), while a Runge–Kutta step keeps the fused
form that `small_solves` arranges around its branch.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from typing import Any

import jax.extend as jex
import jax.numpy as jnp
import numpy as np
from jax import lax

from lagjax._linalg.object_arrays import objects_from_scalars, to_objects

# scalarizable(jaxpr): whether the jaxpr can be evaluated on scalars;
# evaluate(jaxpr, consts, object_arrays) evaluates it on scalars.
Scalarizable = Callable[[Any], bool]
Evaluate = Callable[[Any, Sequence[Any], Sequence[np.ndarray]], list]


def _split(flat: Sequence[Any], avals: Sequence[Any]) -> list[np.ndarray]:
    """Object arrays shaped like `avals` from their elements in order."""
    sizes = [math.prod(aval.shape) for aval in avals]
    bounds = np.cumsum([0, *sizes])
    return [
        objects_from_scalars(flat[start:stop]).reshape(aval.shape)
        for (start, stop), aval in zip(itertools.pairwise(bounds), avals)
    ]


def _elements(arrays: Sequence[Any], avals: Sequence[Any]) -> list:
    """Every element of `arrays` as a scalar of its aval's dtype, in order."""
    return [
        jnp.asarray(element, aval.dtype)
        for array, aval in zip(arrays, avals)
        for element in np.asarray(array, dtype=object).ravel()
    ]


def _as_written(closed: Any, avals: Sequence[Any]) -> Callable:
    """The branch on the arrays rebuilt from its operands' elements."""

    def run(*flat: Any) -> list:
        arrays = [
            jnp.reshape(jnp.stack(list(part.ravel())), aval.shape)
            if part.size
            else jnp.zeros(aval.shape, aval.dtype)
            for part, aval in zip(_split(flat, avals), avals)
        ]
        return jex.core.jaxpr_as_fun(closed)(*arrays)

    return run


def scalar_cond(
    eqn: Any,
    operands: Sequence[np.ndarray],
    scalarizable: Scalarizable,
    evaluate: Evaluate,
) -> list[np.ndarray]:
    """The outputs of a `cond` equation on object arrays of scalars."""
    in_avals = [v.aval for v in eqn.invars[1:]]
    out_avals = [v.aval for v in eqn.outvars]

    def branch(closed: Any) -> Callable:
        if not scalarizable(closed.jaxpr):
            written = _as_written(closed, in_avals)
            return lambda *flat: _elements(
                [to_objects(x) for x in written(*flat)], out_avals
            )

        def on_scalars(*flat: Any) -> list:
            outs = evaluate(closed.jaxpr, closed.consts, _split(flat, in_avals))
            return _elements(outs, out_avals)

        return on_scalars

    index = operands[0][()]
    flat = _elements(operands[1:], in_avals)
    results = lax.switch(index, [branch(b) for b in eqn.params["branches"]], *flat)
    return _split(results, out_avals)
