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

import itertools
import math
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from lagjax._linalg.jaxpr_interpreter import entered, evaluate_jaxpr
from lagjax._linalg.marked_solves import MARKED_SOLVE_NAME
from lagjax._linalg.object_arrays import objects_from_scalars
from lagjax._linalg.object_arrays import to_objects as _to_objects
from lagjax._linalg.scalarized_branches import scalar_cond
from lagjax._linalg.structural_objects import MULTIPLE, STRUCTURAL, structural
from lagjax._linalg.unrolled_ldl import (
    ldl_factor_unrolled,
    ldl_solve_unrolled,
    pivots_sound,
)

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
# Primitives without operands that produce a constant array (jnp.eye, jnp.arange).
_CONSTANTS = frozenset({"iota"})


class _Unsupported(Exception):
    """Raised while checking a jaxpr that this module cannot scalarize."""


def _check(jaxpr: Any, branches: bool = False) -> None:
    for eqn in jaxpr.eqns:
        name = eqn.primitive.name
        if eqn.params.get("name") == MARKED_SOLVE_NAME:
            if len(eqn.invars[1].aval.shape) != 1:
                raise _Unsupported("a marked solve with several right-hand sides")
        elif entered(eqn):
            _check(eqn.params["jaxpr"].jaxpr, branches)
        elif name == "cond" and branches:
            pass  # each branch is judged on its own (`scalarized_branches`)
        elif name == "custom_vmap_call" and branches:
            # `any_in_batch`, the predicate of a branch: its unbatched meaning
            _check(eqn.params["call"].jaxpr, branches)
        elif name not in _ELEMENTWISE | STRUCTURAL | _CONSTANTS:
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


def _scalarizable(jaxpr: Any) -> bool:
    try:
        _check(jaxpr, branches=True)
    except _Unsupported:
        return False
    return True


def _scalar_rule(eqn: Any, operands: list[np.ndarray]) -> list[np.ndarray]:
    """One equation on object arrays of scalars (`evaluate_jaxpr`'s rule)."""
    name = eqn.primitive.name
    if eqn.params.get("name") == MARKED_SOLVE_NAME:
        return _scalar_marked_solve(*operands)
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
        results = structural(eqn, operands)
        results = results if name in MULTIPLE else [results]
    return [np.asarray(value, dtype=object) for value in results]


def _scalar_marked_solve(m: np.ndarray, rhs: np.ndarray) -> list[np.ndarray]:
    """A marked solve (`marked_solves`, in a trace for the Taylor graph) in
    scalars: unrolled LDLᵀ without pivoting, so every operation is a scalar
    product, quotient or difference with its recurrence. M not positive
    definite, or nearly singular, sets the singular flag (the caller turns it
    into NaN or an error) instead of falling back to pivoted LU as
    `solve_unrolled_symmetric` does: LU has no recurrence."""
    n = rhs.shape[0]
    factor = ldl_factor_unrolled([[m[i, j] for j in range(n)] for i in range(n)])
    x = ldl_solve_unrolled(factor, list(rhs))
    singular = jnp.logical_not(pivots_sound(factor))
    return [objects_from_scalars(x), _to_objects(singular)]


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
