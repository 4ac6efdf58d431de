"""Structural primitives on NumPy object arrays of JAX scalars, for `scalarize`.

Slices, reshapes, broadcasts, concatenations and transposes only move scalars
around; contractions (`dot_general`, reductions) become sums of products, and the
cumulative reductions (`jnp.cumsum` & co.) running sums; `pad` (a gradient places
each cotangent in a zero array with it) fills with its value. Each works on the
object arrays `lagjax._linalg.scalarize` evaluates a jaxpr on.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from jax import lax

STRUCTURAL = frozenset(
    [
        "broadcast_in_dim",
        "concatenate",
        "cummax",
        "cummin",
        "cumprod",
        "cumsum",
        "dot_general",
        "pad",  # a gradient places each cotangent in a zero array with it
        "reduce_max",
        "reduce_min",
        "reduce_prod",
        "reduce_sum",
        "reshape",
        "rev",
        "slice",
        "split",
        "squeeze",
        "stack",
        "transpose",
        "unstack",  # JAX ≥ 0.11 unpacks an array (`a, b = q`) with it
    ]
)
# Structural primitives with several outputs.
MULTIPLE = frozenset({"split", "unstack"})
_CUMULATIVE = {
    "cumsum": lax.add,
    "cumprod": lax.mul,
    "cummax": lax.max,
    "cummin": lax.min,
}


def _fold(values: np.ndarray, combine: Callable) -> Any:
    return functools.reduce(combine, values.ravel().tolist())


def _reduce(operand: np.ndarray, axes: Sequence[int], combine: Callable) -> np.ndarray:
    kept = [axis for axis in range(operand.ndim) if axis not in axes]
    moved = np.transpose(operand, (*kept, *axes))
    out_shape = moved.shape[: len(kept)]
    out = np.empty(out_shape, dtype=object)
    for index in np.ndindex(*out_shape):
        # `...` keeps a 0-d array when no axis is reduced (jnp.sum of a scalar):
        # plain indexing would hand _fold the bare element.
        out[index] = _fold(moved[(*index, ...)], combine)
    return out


def _cumulative(
    operand: np.ndarray, axis: int, reverse: bool, combine: Callable
) -> np.ndarray:
    """Running reduction along `axis` (jnp.cumsum & co.), one combine per element."""
    moved = np.moveaxis(operand, axis, -1)
    if moved.shape[-1] == 0:
        return operand
    if reverse:
        moved = moved[..., ::-1]
    out = np.empty(moved.shape, dtype=object)
    for index in np.ndindex(*moved.shape[:-1]):
        running = moved[(*index, 0)]
        out[(*index, 0)] = running
        for k in range(1, moved.shape[-1]):
            running = combine(running, moved[(*index, k)])
            out[(*index, k)] = running
    if reverse:
        out = out[..., ::-1]
    return np.moveaxis(out, -1, axis)


def _dot_general(
    lhs: np.ndarray, rhs: np.ndarray, dimension_numbers, **_
) -> np.ndarray:
    (lhs_contract, rhs_contract), (lhs_batch, rhs_batch) = dimension_numbers
    lhs_free = [d for d in range(lhs.ndim) if d not in (*lhs_contract, *lhs_batch)]
    rhs_free = [d for d in range(rhs.ndim) if d not in (*rhs_contract, *rhs_batch)]
    lhs = np.transpose(lhs, (*lhs_batch, *lhs_free, *lhs_contract))
    rhs = np.transpose(rhs, (*rhs_batch, *rhs_free, *rhs_contract))
    n_batch, n_lf, n_rf = len(lhs_batch), len(lhs_free), len(rhs_free)
    batch_shape = lhs.shape[:n_batch]
    lf_shape = lhs.shape[n_batch : n_batch + n_lf]
    rf_shape = rhs.shape[n_batch : n_batch + n_rf]
    out = np.empty((*batch_shape, *lf_shape, *rf_shape), dtype=object)
    for b in np.ndindex(*batch_shape):
        for i in np.ndindex(*lf_shape):
            for j in np.ndindex(*rf_shape):
                products = lhs[(*b, *i)] * rhs[(*b, *j)]
                # No contracted axis (an outer product, as in a gradient's
                # transposed dot): one product, a JAX scalar, no array to sum.
                out[(*b, *i, *j)] = (
                    _fold(products, lax.add)
                    if isinstance(products, np.ndarray)
                    else products
                )
    return out


def _broadcast_in_dim(
    operand: np.ndarray, shape, broadcast_dimensions, **_
) -> np.ndarray:
    expanded = [1] * len(shape)
    for source, target in enumerate(broadcast_dimensions):
        expanded[target] = operand.shape[source]
    return np.broadcast_to(operand.reshape(expanded), shape)


def _pad(operand: np.ndarray, value: Any, config: Sequence[tuple]) -> np.ndarray:
    """`lax.pad`: per axis, `interior` copies of `value` between elements, then
    `low` and `high` at the ends (negative: that many elements cropped)."""
    out = operand
    for axis, (low, high, interior) in enumerate(config):
        moved = np.moveaxis(out, axis, 0)
        rest = moved.shape[1:]
        size = max(len(moved) * (interior + 1) - interior, 0)
        spaced = _filled((size, *rest), value)
        spaced[:: interior + 1] = moved
        ends = [_filled((max(pad, 0), *rest), value) for pad in (low, high)]
        full = np.concatenate([ends[0], spaced, ends[1]])
        full = full[max(-low, 0) : len(full) - max(-high, 0)]
        out = np.moveaxis(full, 0, axis)
    return out


def _filled(shape: tuple, value: Any) -> np.ndarray:
    """An object array of `shape` holding `value` (a traced scalar too, which
    `np.full` would try to convert to a number)."""
    out = np.empty(shape, dtype=object)
    for index in np.ndindex(*shape):
        out[index] = value
    return out


def structural(eqn: Any, operands: list[np.ndarray]) -> Any:
    """One structural primitive (`STRUCTURAL`) on object arrays of scalars: moved
    elements, or sums and products of them; a list for `MULTIPLE` outputs."""
    name, params = eqn.primitive.name, eqn.params
    if name == "broadcast_in_dim":
        return _broadcast_in_dim(operands[0], **params)
    if name == "reshape":
        return operands[0].reshape(params["new_sizes"])
    if name == "squeeze":
        return np.squeeze(operands[0], axis=tuple(params["dimensions"]))
    if name == "transpose":
        return np.transpose(operands[0], params["permutation"])
    if name == "rev":
        return np.flip(operands[0], axis=tuple(params["dimensions"]))
    if name == "slice":
        strides = params["strides"] or (1,) * operands[0].ndim
        index = tuple(
            slice(start, stop, step)
            for start, stop, step in zip(
                params["start_indices"], params["limit_indices"], strides
            )
        )
        return operands[0][index]
    if name == "concatenate":
        return np.concatenate(operands, axis=params["dimension"])
    if name == "stack":
        return np.stack(operands, axis=params["axis"])
    if name == "split":
        bounds = np.cumsum(params["sizes"])[:-1]
        return np.split(operands[0], bounds, axis=params["axis"])
    if name == "unstack":
        axis = params["axis"]
        parts = np.split(operands[0], operands[0].shape[axis], axis=axis)
        return [np.squeeze(part, axis=axis) for part in parts]  # arrays, even 0-d
    if name == "pad":
        return _pad(operands[0], operands[1].item(), params["padding_config"])
    if name == "dot_general":
        return _dot_general(operands[0], operands[1], params["dimension_numbers"])
    if name in _CUMULATIVE:
        return _cumulative(
            operands[0], params["axis"], params["reverse"], _CUMULATIVE[name]
        )
    combine = {"reduce_sum": lax.add, "reduce_max": lax.max, "reduce_min": lax.min}.get(
        name, lax.mul
    )
    return _reduce(operands[0], params["axes"], combine)
