r"""A float64 function re-run in double-double arithmetic, read off its jaxpr.

`in_double_double(fn)` traces `fn` (float64 arrays in, float64 arrays out) once
and evaluates its equations on double-doubles (`double_double_arithmetic`): each
float value becomes a pair hi + lo, each arithmetic primitive its error-free
counterpart, each structural primitive (reshape, slice, broadcast, select, …)
the same primitive applied to hi and to lo. So a user's potential, its gradient
by autodiff and a whole splitting step run at about 32 significant digits with
no change to the code that wrote them. Integers and booleans pass through;
comparisons of double-doubles are exact.

The supported arithmetic is what Newtonian mechanics with rational forces needs:
+, −, ×, /, √, 1/√, integer powers, |·|, min, max, sums and dot products (summed
pairwise). A transcendental primitive (exp, sin, …) has no double-double rule
here and is refused by name when `fn` is traced.

Cost: a sum about 20 float64 operations, a product about 25, a quotient about
80; what it buys is round-off that no longer random-walks through a long run.

References: D. H. Bailey, "High-precision floating-point arithmetic in
scientific computation", Comput. Sci. Eng. 7, 54 (2005); Hida, Li & Bailey,
ARITH-15 (2001); the JAX documentation, "Writing custom Jaxpr interpreters".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp

import lagjax._linalg.double_double_arithmetic as dd
from lagjax._linalg.double_double_arithmetic import DoubleDouble
from lagjax._linalg.jaxpr_interpreter import evaluate_jaxpr

# Applied to hi and to lo alike: they move or pick elements, or scale exactly.
_ON_BOTH_PARTS = frozenset(
    {"broadcast_in_dim", "reshape", "squeeze", "expand_dims", "transpose", "slice"}
    | {"rev", "copy", "copy_p", "dynamic_slice", "gather", "concatenate", "split"}
    | {"pad", "dynamic_update_slice", "stack", "unstack"}
)
_BINARY = frozenset({"add", "add_any", "sub", "mul", "div"})
_ARITHMETIC = (
    _BINARY
    | {"neg", "sqrt", "rsqrt", "integer_pow", "square", "abs"}
    | {"max", "min", "reduce_sum", "dot_general"}
)
_COMPARISONS = {
    "lt": jnp.less,
    "le": jnp.less_equal,
    "gt": jnp.greater,
    "ge": jnp.greater_equal,
    "eq": jnp.equal,
    "ne": jnp.not_equal,
}


def _is_float(value: Any) -> bool:
    return isinstance(value, DoubleDouble)


def _lift(value: Any) -> Any:
    """A float64 value as a double-double hi + 0; others as they are."""
    if _is_float(value):
        return value
    array = jnp.asarray(value)
    return dd.from_double(array) if jnp.issubdtype(array.dtype, jnp.floating) else array


def _plain(value: Any) -> Any:
    """A constant or literal stays a float64 array: an operation that meets it
    uses the cheaper double-double ⊕ float64 forms."""
    return jnp.asarray(value)


def _on_both_parts(eqn: Any, operands: list[Any]) -> list[Any]:
    """One structural primitive on hi and on lo (index operands shared)."""
    prim, params = eqn.primitive, eqn.params
    part = lambda which: [getattr(x, which) if _is_float(x) else x for x in operands]
    his = prim.bind(*part("hi"), **params)
    los = prim.bind(*part("lo"), **params)
    if prim.multiple_results:
        return [DoubleDouble(h, lo) for h, lo in zip(his, los)]
    return [DoubleDouble(his, los)]


def _pairwise_sum(x: DoubleDouble, axis: int) -> DoubleDouble:
    """Σ over `axis`, by halving: log₂(n) vector additions of double-doubles."""
    x = DoubleDouble(jnp.moveaxis(x.hi, axis, 0), jnp.moveaxis(x.lo, axis, 0))
    while x.hi.shape[0] > 1:
        n = x.hi.shape[0]
        half = n // 2
        paired = dd.add(
            DoubleDouble(x.hi[:half], x.lo[:half]),
            DoubleDouble(x.hi[half : 2 * half], x.lo[half : 2 * half]),
        )
        if n % 2:
            paired = DoubleDouble(
                jnp.concatenate([paired.hi, x.hi[-1:]]),
                jnp.concatenate([paired.lo, x.lo[-1:]]),
            )
        x = paired
    if x.hi.shape[0] == 0:
        zeros = jnp.zeros(x.hi.shape[1:], x.hi.dtype)
        return DoubleDouble(zeros, zeros)
    return DoubleDouble(x.hi[0], x.lo[0])


def _reduce_sum(x: DoubleDouble, axes: Sequence[int]) -> DoubleDouble:
    for axis in sorted(axes, reverse=True):
        x = _pairwise_sum(x, axis)
    return x


def _dot_general(x: DoubleDouble, y: DoubleDouble, dimension_numbers) -> DoubleDouble:
    """dot_general as products of aligned elements, then pairwise sums: the
    operands laid out (batch, free, contracted), multiplied by broadcasting."""
    (x_contract, y_contract), (x_batch, y_batch) = dimension_numbers
    x_free = [d for d in range(x.hi.ndim) if d not in (*x_contract, *x_batch)]
    y_free = [d for d in range(y.hi.ndim) if d not in (*y_contract, *y_batch)]

    def arrange(v: DoubleDouble, batch, free, contract, free_first: bool):
        order = (*batch, *free, *contract)
        shape = [v.hi.shape[d] for d in order]
        nb, nf = len(batch), len(free)
        b, f, c = shape[:nb], shape[nb : nb + nf], shape[nb + nf :]
        size = lambda dims: math.prod(dims)
        new = (
            (size(b), size(f), 1, size(c))
            if free_first
            else (size(b), 1, size(f), size(c))
        )
        move = lambda a: jnp.transpose(a, order).reshape(new)
        return DoubleDouble(move(v.hi), move(v.lo)), b, f

    xs, batch_shape, x_free_shape = arrange(x, x_batch, x_free, x_contract, True)
    ys, _, y_free_shape = arrange(y, y_batch, y_free, y_contract, False)
    shape = jnp.broadcast_shapes(xs.hi.shape, ys.hi.shape)
    grow = lambda v: DoubleDouble(*(jnp.broadcast_to(a, shape) for a in v))
    summed = _pairwise_sum(dd.multiply(grow(xs), grow(ys)), axis=3)
    final = (*batch_shape, *x_free_shape, *y_free_shape)
    return DoubleDouble(summed.hi.reshape(final), summed.lo.reshape(final))


def _select_n(which: Any, *cases: Any) -> Any:
    if not any(_is_float(c) for c in cases):
        return jax.lax.select_n(which, *cases)
    lifted = [_lift(c) for c in cases]
    return DoubleDouble(
        jax.lax.select_n(which, *(c.hi for c in lifted)),
        jax.lax.select_n(which, *(c.lo for c in lifted)),
    )


def _extremum(x: DoubleDouble, y: DoubleDouble, larger: bool) -> DoubleDouble:
    sign = dd.sign_of_difference(x, y)
    take_x = sign >= 0 if larger else sign <= 0
    return _select_n(~take_x, x, y)


def _mixed(name: str, a: Any, b: Any) -> Any:
    """A binary +, −, ×, /; a float64 operand takes the cheaper mixed forms, two
    float64 operands the error-free sum or product."""
    if not _is_float(a) and not _is_float(b):
        if name in ("add", "add_any", "sub"):
            return dd.two_sum(a, b if name != "sub" else -b)
        if name == "mul":
            return dd.two_product(a, b)
        return dd.divide_double(dd.from_double(a), b)
    if name == "sub":
        return _mixed("add", a, dd.negate(b) if _is_float(b) else -b)
    if name in ("add", "add_any", "mul") and not _is_float(a):
        a, b = b, a  # commutative: the double-double first
    if name in ("add", "add_any"):
        return dd.add(a, b) if _is_float(b) else dd.add_double(a, b)
    if name == "mul":
        return dd.multiply(a, b) if _is_float(b) else dd.multiply_double(a, b)
    if not _is_float(b):
        return dd.divide_double(a, b)
    return dd.divide(_lift(a), b)


def _arithmetic(name: str, params: dict, operands: list[Any]) -> Any:
    if name in _BINARY:
        return _mixed(name, *operands)
    operands = [_lift(x) for x in operands]
    a = operands[0]
    if name == "neg":
        return dd.negate(a)
    if name == "sqrt":
        return dd.square_root(a)
    if name == "rsqrt":
        return dd.divide(dd.from_double(jnp.ones_like(a.hi)), dd.square_root(a))
    if name == "integer_pow":
        return dd.integer_power(a, params["y"])
    if name == "square":
        return dd.multiply(a, a)
    if name == "abs":
        return _select_n(a.hi < 0, a, dd.negate(a))
    if name in ("max", "min"):
        return _extremum(a, operands[1], larger=name == "max")
    if name == "reduce_sum":
        return _reduce_sum(a, params["axes"])
    if name == "dot_general":
        return _dot_general(a, operands[1], params["dimension_numbers"])
    raise NotImplementedError(
        f"lagjax double-double: no rule for the primitive {name!r} (supported: "
        "+, −, ×, /, √, 1/√, integer powers, |·|, min, max, sums, dot products)"
    )


def _convert(eqn: Any, value: Any) -> Any:
    target = eqn.params["new_dtype"]
    if jnp.issubdtype(target, jnp.floating):
        if _is_float(value):
            return value
        return dd.from_double(jnp.asarray(value).astype(target))
    if _is_float(value):  # to an integer: from the rounded value
        return dd.to_double(value).astype(target)
    return jnp.asarray(value).astype(target)


def _rule(eqn: Any, operands: list[Any]) -> list[Any]:
    name = eqn.primitive.name
    floats = [x for x in operands if _is_float(x)]
    if name in ("custom_jvp_call", "custom_vjp_call"):
        # The primal computation; derivatives of the result are not asked for.
        closed = eqn.params["call_jaxpr"]
        return _evaluate(closed.jaxpr, closed.consts, operands)
    if name == "convert_element_type":
        return [_convert(eqn, operands[0])]
    if name == "select_n":
        return [_select_n(*operands)]
    # Arithmetic on float64 constants runs in double-double too: a constant the
    # float64 program computes (autodiff writes 1/7 for a division by 7) is
    # part of what is evaluated more precisely.
    computes_a_float = name in _ARITHMETIC and any(map(_is_float_aval, eqn.outvars))
    if not floats and not computes_a_float:
        return (
            list(eqn.primitive.bind(*operands, **eqn.params))
            if (eqn.primitive.multiple_results)
            else [eqn.primitive.bind(*operands, **eqn.params)]
        )
    if name in _BINARY:
        return [_mixed(name, *operands)]
    operands = [_lift(x) if _is_float_aval(v) and not _is_float(x) else x
                for x, v in zip(operands, eqn.invars)]  # fmt: skip
    if name in _COMPARISONS:
        sign = dd.sign_of_difference(*operands)
        return [_COMPARISONS[name](sign, 0)]
    if name in _ON_BOTH_PARTS:
        return _on_both_parts(eqn, operands)
    return [_arithmetic(name, eqn.params, operands)]


def _is_float_aval(var: Any) -> bool:
    dtype = getattr(getattr(var, "aval", None), "dtype", None)
    return dtype is not None and jnp.issubdtype(dtype, jnp.floating)


def _evaluate(jaxpr: Any, consts: Sequence[Any], inputs: Sequence[Any]) -> list:
    return evaluate_jaxpr(jaxpr, consts, inputs, _rule, literal=_plain, const=_plain)


def in_double_double(fn: Callable[..., Any]) -> Callable[..., Any]:
    """`fn(*args)` (pytrees of float64 arrays) evaluated in double-double.

    The returned function takes and returns the same pytrees with every float
    leaf a `DoubleDouble` (hi, lo); non-float leaves are passed as they are.
    """

    def run(*args: Any) -> Any:
        is_leaf = lambda x: isinstance(x, DoubleDouble)
        leaves, treedef = jax.tree_util.tree_flatten(args, is_leaf=is_leaf)
        examples = [x.hi if _is_float(x) else x for x in leaves]
        closed, shape = jax.make_jaxpr(
            lambda *flat: fn(*jax.tree_util.tree_unflatten(treedef, flat)),
            return_shape=True,
        )(*examples)
        outputs = _evaluate(closed.jaxpr, closed.consts, leaves)
        return jax.tree_util.tree_unflatten(
            jax.tree_util.tree_structure(shape), outputs
        )

    return run


def split_tree(tree: Any) -> Any:
    """A pytree of float64 arrays as the same pytree of `DoubleDouble`s (lo = 0)."""
    return jax.tree_util.tree_map(dd.from_double, tree)


def rounded_tree(tree: Any) -> Any:
    """A pytree's `DoubleDouble`s as float64 arrays (each rounded to nearest);
    other leaves as they are."""
    return jax.tree_util.tree_map(
        lambda x: dd.to_double(x) if _is_float(x) else x, tree, is_leaf=_is_float
    )
