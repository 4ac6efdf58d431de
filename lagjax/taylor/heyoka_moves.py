r"""Data moves and equations on numbers in the heyoka translation.

Two kinds of equation of the jaxpr walk (`heyoka_expressions`) need no heyoka
function, only JAX's exact meaning:

- **Equations on numbers** (no operand depends on the state): evaluated by NumPy
  where it computes what JAX computes (arithmetic, comparisons and data moves,
  cast to JAX's output dtype), else by JAX itself (`bind`), so integer indexing,
  iotas and constant tables mean exactly what they mean in JAX. NumPy first
  spares an XLA compilation per new shape and parameter (a few tenths of a
  second each on a loaded CPU).
- **Data moves** (`DATA_MOVES`: slice, reshape, broadcast, gather, scatter,
  concatenate, split, unstack, pad, a select with a numeric predicate, …) on
  arrays of objects (heyoka expressions or numbers): NumPy applies the move
  where it has the same operation; otherwise JAX applies the primitive to an
  array of element indices and the result picks the elements (`move`). The
  index operands must be numbers.

References: the JAX documentation, `jax.lax` (the primitives' semantics) and
"Writing custom Jaxpr interpreters in JAX"; the NumPy documentation,
`numpy.take_along_axis`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import jax.numpy as jnp
import numpy as np

from lagjax.taylor.heyoka_rules import (
    UnsupportedPrimitiveError,
    object_array,
    symbolic,
)

# Primitives that only move elements: the operand positions that hold data (the
# others — indices, start positions, predicates — must be numbers).
_SINGLE_DATA_OPERAND = (
    "slice",
    "squeeze",
    "reshape",
    "broadcast_in_dim",
    "transpose",
    "rev",
    "expand_dims",
    "gather",
    "dynamic_slice",
    "split",
    "unstack",  # JAX ≥ 0.11 unpacks an array (`a, b = q`) with it
    "copy",
    "copy_p",
)
DATA_MOVES: dict[str, Callable[[int], Sequence[int]]] = {
    **dict.fromkeys(_SINGLE_DATA_OPERAND, lambda k: (0,)),
    "concatenate": range,
    "stack": range,
    "pad": lambda k: (0, 1),
    "scatter": lambda k: (0, 2),
    "dynamic_update_slice": lambda k: (0, 1),
    "select_n": lambda k: range(1, k),
}


# Equations on numbers that NumPy evaluates with JAX's meaning (cast to JAX's
# output dtype), sparing an XLA compilation per new shape and parameter.
NUMPY_ARITHMETIC: dict[str, Callable[..., Any]] = {
    "add": np.add,
    "sub": np.subtract,
    "mul": np.multiply,
    "neg": np.negative,
    "max": np.maximum,
    "min": np.minimum,
    "eq": np.equal,
    "ne": np.not_equal,
    "lt": np.less,
    "le": np.less_equal,
    "gt": np.greater,
    "ge": np.greater_equal,
    "and": np.bitwise_and,
    "or": np.bitwise_or,
    "not": np.invert,
    "abs": np.abs,
    "sign": np.sign,
    "convert_element_type": lambda x: x,
}


def bind(eqn: Any, operands: Sequence[Any]) -> list[np.ndarray]:
    """An equation on numbers only: evaluated as JAX evaluates it — by NumPy where
    the two agree, else by JAX itself."""
    name = eqn.primitive.name
    if name in NUMPY_MOVES and not (name == "reshape" and eqn.params.get("dimensions")):
        out = NUMPY_MOVES[name](eqn.params, *[np.asarray(x) for x in operands])
        return [np.asarray(x) for x in (out if isinstance(out, list) else [out])]
    if name in NUMPY_ARITHMETIC:
        dtype = eqn.outvars[0].aval.dtype
        return [np.asarray(NUMPY_ARITHMETIC[name](*operands)).astype(dtype)]
    return jax_bind(eqn, operands)


def jax_bind(eqn: Any, operands: Sequence[Any]) -> list[np.ndarray]:
    out = eqn.primitive.bind(*operands, **eqn.params)
    outs = out if eqn.primitive.multiple_results else [out]
    return [np.asarray(x) for x in outs]


def move(eqn: Any, operands: Sequence[Any], data: Sequence[int]) -> list[np.ndarray]:
    """A data-movement primitive: by NumPy where it has the same operation, else
    applied by JAX to element indices, the result picking the elements."""
    name, p = eqn.primitive.name, eqn.params
    if name in NUMPY_MOVES and not (name == "reshape" and p.get("dimensions")):
        out = NUMPY_MOVES[name](p, *[object_array(x) for x in operands])
        return [object_array(x) for x in (out if isinstance(out, list) else [out])]
    pool, indexed, offset = [], list(operands), 0
    for i, operand in enumerate(operands):
        if i in data:
            values = np.asarray(operand, dtype=object)
            indexed[i] = jnp.arange(offset, offset + values.size).reshape(values.shape)
            pool.append(values.ravel())
            offset += values.size
        elif symbolic(operand):
            raise UnsupportedPrimitiveError(
                eqn.primitive.name, "an index or position that depends on the state"
            )
    elements = np.concatenate(pool)
    return [
        elements[index.ravel()].reshape(index.shape) for index in jax_bind(eqn, indexed)
    ]


def _slice(p: dict, x: np.ndarray) -> np.ndarray:
    strides = p["strides"] or [1] * x.ndim
    bounds = zip(p["start_indices"], p["limit_indices"], strides)
    return x[tuple(slice(*bound) for bound in bounds)]


def _choose(p: dict, predicate: np.ndarray, *cases: np.ndarray) -> np.ndarray:
    """`select_n` with a numeric predicate: case `predicate` at every element."""
    index, *arrays = np.broadcast_arrays(np.asarray(predicate).astype(np.intp), *cases)
    return np.take_along_axis(np.stack(arrays), index[None], axis=0)[0]


def _broadcast_in_dim(p: dict, x: np.ndarray) -> np.ndarray:
    shape, dims = p["shape"], p["broadcast_dimensions"]
    expanded = [1] * len(shape)
    for i, d in enumerate(dims):
        expanded[d] = x.shape[i]
    return np.broadcast_to(x.reshape(expanded), shape)


# Data moves that NumPy performs on arrays of objects directly (no JAX call).
NUMPY_MOVES: dict[str, Callable[..., Any]] = {
    "slice": _slice,
    "squeeze": lambda p, x: np.squeeze(x, axis=tuple(p["dimensions"])),
    "reshape": lambda p, x: x.reshape(p["new_sizes"]),
    "broadcast_in_dim": _broadcast_in_dim,
    "transpose": lambda p, x: x.transpose(p["permutation"]),
    "rev": lambda p, x: np.flip(x, tuple(p["dimensions"])),
    "expand_dims": lambda p, x: np.expand_dims(x, tuple(p["dimensions"])),
    "concatenate": lambda p, *xs: np.concatenate(xs, axis=p["dimension"]),
    "stack": lambda p, *xs: np.stack(xs, axis=p["axis"]),
    "split": lambda p, x: np.split(x, np.cumsum(p["sizes"])[:-1], axis=p["axis"]),
    "select_n": _choose,
    # each output the operand's slice at one index along `axis`
    "unstack": lambda p, x: list(np.moveaxis(x, p["axis"], 0)),
    "copy": lambda p, x: x,
    "copy_p": lambda p, x: x,
}
