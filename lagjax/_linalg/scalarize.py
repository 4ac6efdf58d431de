"""Re-express a function of small arrays as arithmetic on scalars.

Why: on CPU, XLA pays per kernel, and the small array operations a user writes in a
Lagrangian (`qd @ M(q) @ qd`, `jnp.array([[a, b], [b, c]])`, `q[0]`) — and, more,
their derivatives (pads, slices, small dots) — split an integration step into dozens
of kernels. The same arithmetic done on scalars fuses into one kernel, as fast as
hand-written equations of motion (see `benchmarks/derivation_overhead.py`).

How: the function is traced once to a jaxpr; the jaxpr is then evaluated with every
array held as a NumPy object array of JAX scalars. Element-wise primitives act per
element, structural ones (slice, reshape, broadcast, concatenate, transpose) only move
scalars around, contractions (dot_general, reductions) become sums of products, and
cumulative reductions (`jnp.cumsum` & co., as in a chain's link positions) running
sums.
A primitive outside the supported set, or an intermediate array larger than
`MAX_SCALARIZED_SIZE`, makes `scalarize` return None and the caller keeps the
function as written — the result is the same either way, only the speed differs.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from lagjax._linalg.jaxpr_interpreter import CALLS, evaluate_jaxpr
from lagjax._linalg.object_arrays import objects_from_scalars
from lagjax._linalg.object_arrays import to_objects as _to_objects
from lagjax._linalg.scalarized_branches import scalar_cond

MAX_SCALARIZED_SIZE = 64

_ELEMENTWISE = frozenset(
    [
        "abs",
        "acos",
        "acosh",
        "add",
        "add_any",  # the sum of cotangents in a transposed (grad) jaxpr
        "and",
        "asin",
        "asinh",
        "atan",
        "atan2",
        "atanh",
        "cbrt",
        "ceil",
        "clamp",
        "copy",
        "copy_p",
        "convert_element_type",
        "cos",
        "cosh",
        "div",
        "eq",
        "erf",
        "erfc",
        "exp",
        "exp2",
        "expm1",
        "floor",
        "ge",
        "gt",
        "integer_pow",
        "is_finite",
        "le",
        "lgamma",
        "log",
        "log1p",
        "logistic",
        "lt",
        "max",
        "min",
        "mul",
        "ne",
        "neg",
        "not",
        "or",
        "pow",
        "rem",
        "round",
        "rsqrt",
        "select_n",
        "sign",
        "sin",
        "sinh",
        "sqrt",
        "square",
        "stop_gradient",
        "sub",
        "tan",
        "tanh",
        "xor",
    ]
)
_STRUCTURAL = frozenset(
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
_MULTIPLE = frozenset({"split", "unstack"})
_CUMULATIVE = {
    "cumsum": lax.add,
    "cumprod": lax.mul,
    "cummax": lax.max,
    "cummin": lax.min,
}
# Primitives without operands that produce a constant array (jnp.eye, jnp.arange).
_CONSTANTS = frozenset({"iota"})


class _Unsupported(Exception):
    """Raised while checking a jaxpr that this module cannot scalarize."""


def _check(jaxpr: Any, branches: bool = False) -> None:
    for eqn in jaxpr.eqns:
        name = eqn.primitive.name
        if name in CALLS:
            _check(eqn.params["jaxpr"].jaxpr, branches)
        elif name == "cond" and branches:
            pass  # each branch is judged on its own (`scalarized_branches`)
        elif name == "custom_vmap_call" and branches:
            # `any_in_batch`, the predicate of a branch: its unbatched meaning
            _check(eqn.params["call"].jaxpr, branches)
        elif name not in _ELEMENTWISE | _STRUCTURAL | _CONSTANTS:
            raise _Unsupported(name)
        for var in (*eqn.invars, *eqn.outvars):
            if math.prod(getattr(var.aval, "shape", ())) > MAX_SCALARIZED_SIZE:
                raise _Unsupported(f"{name} on an array of shape {var.aval.shape}")


def _elementwise(eqn: Any, operands: Sequence[np.ndarray]) -> np.ndarray:
    shape = np.broadcast_shapes(*(op.shape for op in operands))
    operands = [np.broadcast_to(op, shape) for op in operands]
    out = np.empty(shape, dtype=object)
    for index in np.ndindex(*shape):
        out[index] = eqn.primitive.bind(*(op[index] for op in operands), **eqn.params)
    return out


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


def _structural(eqn: Any, operands: list[np.ndarray]) -> Any:
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


def _scalarizable(jaxpr: Any) -> bool:
    try:
        _check(jaxpr, branches=True)
    except _Unsupported:
        return False
    return True


def _scalar_rule(eqn: Any, operands: list[np.ndarray]) -> list[np.ndarray]:
    """One equation on object arrays of scalars (`evaluate_jaxpr`'s rule)."""
    name = eqn.primitive.name
    if name == "cond":  # only where the caller asked for branches (`_check`)
        return scalar_cond(eqn, operands, _scalarizable, _evaluate)
    if name == "custom_vmap_call":  # likewise
        return _evaluate(eqn.params["call"].jaxpr, eqn.params["call"].consts, operands)
    if name in _ELEMENTWISE:
        results = [_elementwise(eqn, operands)]
    elif name in _CONSTANTS:
        # Evaluated now, even inside jit: the value depends on no input.
        with jax.ensure_compile_time_eval():
            results = [_to_objects(np.asarray(eqn.primitive.bind(**eqn.params)))]
    else:
        results = _structural(eqn, operands)
        results = results if name in _MULTIPLE else [results]
    return [np.asarray(value, dtype=object) for value in results]


def _evaluate(jaxpr: Any, consts: Sequence[Any], inputs: Sequence[np.ndarray]) -> list:
    return evaluate_jaxpr(
        jaxpr,
        consts,
        inputs,
        _scalar_rule,
        literal=lambda value: _to_objects(np.asarray(value)),
        const=_to_objects,
    )


def scalarize(
    fn: Callable[..., jax.Array], *example: Any, branches: bool = False
) -> Callable | None:
    """A scalar-argument twin of `fn(*arrays) -> scalar`, or None if not possible.

    `example` are arrays (or tracers) with the shapes and dtypes `fn` will be called
    with. The twin takes, for each argument, an object array of that shape holding
    JAX scalars, and returns the scalar result built from scalar operations only.
    With `branches`, a `lax.cond` is kept as a `lax.switch` on scalars
    (`scalarized_branches`); without, it makes `scalarize` return None.
    """
    twin = scalarize_outputs(fn, *example, branches=branches)
    if twin is None:
        return None

    def scalar_fn(*object_arrays: np.ndarray) -> Any:
        (result,) = twin(*object_arrays)
        return result[()]

    return scalar_fn


def scalarize_outputs(
    fn: Callable[..., Any], *example: Any, branches: bool = False
) -> Callable | None:
    """As `scalarize`, for a `fn` of several outputs (a value and its gradient):
    the twin returns the list of `fn`'s flattened outputs, each an object array
    of JAX scalars."""
    closed = jax.make_jaxpr(fn)(*example)
    try:
        _check(closed.jaxpr, branches)
    except _Unsupported:
        return None

    def scalar_fn(*object_arrays: np.ndarray) -> list[np.ndarray]:
        return _evaluate(closed.jaxpr, closed.consts, object_arrays)

    return scalar_fn


def as_object_array(value: Any) -> np.ndarray:
    """Public alias of the element split used for inputs (e.g. parameters in args)."""
    return _to_objects(value)


def scalar_argument_function(fn: Callable[..., Any], *examples: Any) -> Callable:
    """`fn(*arrays)` re-expressed as a function of all the arrays' elements.

    The returned function takes the elements of every argument, flattened and in
    order, as separate JAX scalars. It evaluates the scalar twin of `fn` when
    `scalarize` can build one, and otherwise stacks the scalars back into arrays.
    """
    shapes = [np.shape(example) for example in examples]
    bounds = np.cumsum([0] + [math.prod(shape) for shape in shapes])
    twin = scalarize(fn, *examples)

    def chunks(scalars):
        return [scalars[start:stop] for start, stop in itertools.pairwise(bounds)]

    if twin is None:

        def stacked(*scalars):
            arrays = [
                jnp.reshape(jnp.stack(chunk), shape)
                for chunk, shape in zip(chunks(scalars), shapes)
            ]
            return fn(*arrays)

        return stacked

    def scalar(*scalars):
        arrays = [
            objects_from_scalars(chunk).reshape(shape)
            for chunk, shape in zip(chunks(scalars), shapes)
        ]
        return twin(*arrays)

    return scalar
