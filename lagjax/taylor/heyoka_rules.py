r"""How each JAX primitive of a vector field becomes heyoka expressions.

The rules of the jaxpr walk in `heyoka_expressions`. A value is a NumPy array: of
numbers where it does not depend on the state, of objects (heyoka expressions or
numbers) where it does. Four kinds of rule, tried in this order:

1. **Numbers only** (no operand depends on the state) and 2. **data movement**
   (`DATA_MOVES`: slice, gather, unstack, a select with a numeric predicate, …):
   `heyoka_moves`, by NumPy where it computes what JAX computes, else by JAX
   itself, on the numbers or on arrays of element indices.
3. **Element maps** (`elementwise_rules`): heyoka's arithmetic, elementary functions
   and relational operators; NumPy's where every operand is a number. `abs`, `max`,
   `min` and `sign` are `heyoka.select`s on comparisons (piecewise smooth: their
   Taylor coefficients are those of the selected branch).
4. **Structured rules** (`SYMBOLIC_RULES`): `integer_pow`, `convert_element_type`,
   `select_n`, `dot_general`, reductions and cumulative sums; control flow is in
   `heyoka_control`.

References: F. Biscani & D. Izzo, "Revisiting high-order Taylor methods for
astrodynamics and celestial mechanics", MNRAS 504 (2021) 2614 (heyoka's expression
system and `select`); the JAX documentation, `jax.lax` (the primitives' semantics).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import jax
import numpy as np


class UnsupportedPrimitiveError(NotImplementedError):
    """A primitive of the vector field that heyoka's expressions cannot express."""

    def __init__(self, primitive: str, why: str = "") -> None:
        self.primitive = primitive
        reason = f" ({why})" if why else ""
        super().__init__(
            f"the heyoka backend cannot translate the JAX primitive `{primitive}`"
            f"{reason}. Integrate this system with lagjax's own solvers "
            "(lj.simulate, or the JAX-native lj.Taylor) instead."
        )


class Walk(Protocol):
    """What a rule may ask of the translation in progress."""

    hy: Any
    poisoned: list[str]
    elementwise: dict[str, Callable[..., Any]]

    def evaluate(
        self, jaxpr: Any, consts: Sequence[Any], inputs: Sequence[Any]
    ) -> list[Any]: ...

    def enter(self, inner: Any, operands: Sequence[Any]) -> list[Any]: ...


def symbolic(value: Any) -> bool:
    """Whether `value` depends on the state (an array of objects)."""
    return isinstance(value, np.ndarray) and value.dtype == object


def as_expression(hy: Any, element: Any) -> Any:
    if isinstance(element, hy.expression):
        return element
    return hy.expression(float(element))


def element_map(function: Callable[..., Any], operands: Sequence[Any]) -> np.ndarray:
    """`function` applied element by element to broadcast operands."""
    arrays = np.broadcast_arrays(*[np.asarray(x, dtype=object) for x in operands])
    return object_array(np.frompyfunc(function, len(arrays), 1)(*arrays))


def object_array(value: Any) -> np.ndarray:
    """`value` as an array of objects; a lone element (NumPy returns those for
    zero-dimensional results) becomes a zero-dimensional array."""
    if isinstance(value, np.ndarray):
        return value.astype(object, copy=False)
    array = np.empty((), dtype=object)
    array[()] = value
    return array


@functools.cache
def elementwise_rules(hy: Any) -> dict[str, Callable[..., Any]]:
    """Element rules: heyoka's function for expressions, NumPy's for numbers."""

    def rule(symbolic_fn: Callable[..., Any], numeric_fn: Callable[..., Any]):
        def apply(*elements):
            if any(isinstance(e, hy.expression) for e in elements):
                return symbolic_fn(*[as_expression(hy, e) for e in elements])
            return numeric_fn(*[np.float64(e) for e in elements]).item()

        return apply

    def abs_(x):
        return hy.select(hy.gte(x, 0.0), x, -x)

    def sign(x):
        return hy.select(hy.gt(x, 0.0), 1.0, hy.select(hy.lt(x, 0.0), -1.0, 0.0))

    rules = {
        "add": rule(lambda a, b: a + b, np.add),
        "add_any": rule(lambda a, b: a + b, np.add),
        "sub": rule(lambda a, b: a - b, np.subtract),
        "mul": rule(lambda a, b: a * b, np.multiply),
        "div": rule(lambda a, b: a / b, np.divide),
        "neg": rule(lambda a: -a, np.negative),
        "pow": rule(lambda a, b: a**b, np.power),
        "rsqrt": rule(lambda a: a**-0.5, lambda a: 1 / np.sqrt(a)),
        "square": rule(lambda a: a * a, np.square),
        "exp2": rule(lambda a: hy.exp(a * float(np.log(2.0))), np.exp2),
        "logistic": rule(hy.sigmoid, lambda a: 1 / (1 + np.exp(-a))),
        "abs": rule(abs_, np.abs),
        "sign": rule(sign, np.sign),
        "max": rule(lambda a, b: hy.select(hy.gt(a, b), a, b), np.maximum),
        "min": rule(lambda a, b: hy.select(hy.lt(a, b), a, b), np.minimum),
        "and": rule(lambda a, b: hy.logical_and([a, b]), np.logical_and),
        "or": rule(lambda a, b: hy.logical_or([a, b]), np.logical_or),
        "not": rule(lambda a: hy.eq(a, 0.0), np.logical_not),
        "atan2": rule(hy.atan2, np.arctan2),
    }
    relations = dict(eq="eq", ne="neq", lt="lt", le="lte", gt="gt", ge="gte")
    for jax_name, hy_name in relations.items():
        rules[jax_name] = rule(getattr(hy, hy_name), getattr(np, _NUMPY[jax_name]))
    for name in ("sqrt", "exp", "log", "log1p", "expm1", "sin", "cos", "tan"):
        rules[name] = rule(getattr(hy, name), getattr(np, name))
    for name in ("sinh", "cosh", "tanh"):
        rules[name] = rule(getattr(hy, name), getattr(np, name))
    for name in ("asin", "acos", "atan", "asinh", "acosh", "atanh"):
        rules[name] = rule(getattr(hy, name), getattr(np, "arc" + name[1:]))
    for name in ("erf", "erfc"):
        rules[name] = rule(getattr(hy, name), getattr(jax.scipy.special, name))
    return rules


_NUMPY = dict(
    eq="equal",
    ne="not_equal",
    lt="less",
    le="less_equal",
    gt="greater",
    ge="greater_equal",
)


def select_elements(hy: Any, predicate: Any, cases: Sequence[Any]) -> np.ndarray:
    """`lax.select_n` element by element, the predicate possibly state-dependent."""

    def pick(p, *options):
        if not isinstance(p, hy.expression):
            return options[int(p)]
        result = as_expression(hy, options[0])
        for k in range(1, len(options)):
            chosen = p if len(options) == 2 else hy.eq(p, float(k))
            result = hy.select(chosen, as_expression(hy, options[k]), result)
        return result

    return element_map(pick, [predicate, *cases])


def _select_n(walk: Walk, eqn: Any, operands: list[Any]) -> list[Any]:
    return [select_elements(walk.hy, operands[0], operands[1:])]


def _integer_pow(walk: Walk, eqn: Any, operands: list[Any]) -> list[Any]:
    """x**n; of an expression, n ≥ 3 as products of heyoka's squares: heyoka's
    `pow` with a real exponent has Taylor recurrences that divide by the base,
    NaN where it is zero (heyoka 7.13: `x**3` from x = 0 ends in err_nf_state,
    so did the FPU chain from rest), while squares and products are exact there."""
    n, expression = eqn.params["y"], walk.hy.expression

    def power(a: Any, n: int) -> Any:
        if n == 1:
            return a
        if n < 3 or not isinstance(a, expression):
            return a**n
        half = power(a, n // 2)
        return half * half * a if n % 2 else half * half

    return [element_map(lambda a: power(a, n), operands)]


def _convert(walk: Walk, eqn: Any, operands: list[Any]) -> list[Any]:
    """Float to float keeps the expression; a comparison (bool) read as a number is
    heyoka's 0/1; a state-dependent float made bool is `x != 0`; float to integer
    has no Taylor series and is refused."""
    hy, (x,) = walk.hy, operands
    source, target = eqn.invars[0].aval.dtype, np.dtype(eqn.params["new_dtype"])
    if target == np.bool_ and source != np.bool_:
        return [element_map(lambda a: hy.neq(as_expression(hy, a), 0.0), [x])]
    if np.issubdtype(target, np.integer) and np.issubdtype(source, np.floating):
        raise UnsupportedPrimitiveError(
            "convert_element_type", "a state-dependent float converted to an integer"
        )
    return [x]


def _dot_general(walk: Walk, eqn: Any, operands: list[Any]) -> list[Any]:
    """Sums of products, terms with a numeric zero factor left out; products and
    two-term sums by the walk's element rules (which fold negations)."""
    (lc, rc), (lb, rb) = eqn.params["dimension_numbers"]
    lhs, rhs = (np.asarray(x, dtype=object) for x in operands)
    lf = [d for d in range(lhs.ndim) if d not in lc and d not in lb]
    rf = [d for d in range(rhs.ndim) if d not in rc and d not in rb]
    batch = [lhs.shape[d] for d in lb]
    shape = (*batch, *[lhs.shape[d] for d in lf], *[rhs.shape[d] for d in rf])
    k = int(np.prod([lhs.shape[d] for d in lc]))
    a = lhs.transpose([*lb, *lf, *lc]).reshape(int(np.prod(batch)), -1, k)
    b = rhs.transpose([*rb, *rc, *rf]).reshape(int(np.prod(batch)), k, -1)
    out = np.empty((a.shape[0], a.shape[1], b.shape[2]), dtype=object)
    mul, add = walk.elementwise["mul"], walk.elementwise["add"]
    for index in np.ndindex(*out.shape):
        i, m, n = index
        terms = [
            mul(x, y) if _symbolic_element(walk.hy, x, y) else x * y
            for x, y in zip(a[i, m], b[i, :, n])
            if not (_is_zero(x) or _is_zero(y))
        ]
        both = len(terms) == 2 and _symbolic_element(walk.hy, *terms)
        out[index] = add(*terms) if both else _sum(walk.hy, terms)
    return [out.reshape(shape)]


def _symbolic_element(hy: Any, *elements: Any) -> bool:
    return any(isinstance(e, hy.expression) for e in elements)


def _is_zero(element: Any) -> bool:
    return isinstance(element, (bool, int, float, np.number)) and element == 0


def _sum(hy: Any, terms: list[Any]) -> Any:
    if not terms:
        return 0.0
    if any(isinstance(t, hy.expression) for t in terms):
        return hy.sum([as_expression(hy, t) for t in terms])
    return float(sum(terms))


def _reduction(combine: str) -> Callable[[Walk, Any, list[Any]], list[Any]]:
    """reduce_sum / reduce_max / reduce_min / reduce_prod over `axes`."""

    def rule(walk: Walk, eqn: Any, operands: list[Any]) -> list[Any]:
        ufunc = np.frompyfunc(walk.elementwise[combine], 2, 1)
        x = np.asarray(operands[0], dtype=object)
        for axis in sorted(eqn.params["axes"], reverse=True):
            x = (
                ufunc.reduce(x, axis=axis)
                if x.shape[axis]
                else _empty(combine, x, axis)
            )
        return [object_array(x)]

    return rule


def _empty(combine: str, x: np.ndarray, axis: int) -> np.ndarray:
    if combine not in ("add", "mul"):
        raise UnsupportedPrimitiveError(f"reduce_{combine}", "an empty reduction")
    return np.full(np.delete(x.shape, axis), 0.0 if combine == "add" else 1.0, object)


def _cumulative(combine: str) -> Callable[[Walk, Any, list[Any]], list[Any]]:
    """cumsum / cumprod / cummax / cummin along `axis`, maybe reversed."""

    def rule(walk: Walk, eqn: Any, operands: list[Any]) -> list[Any]:
        ufunc = np.frompyfunc(walk.elementwise[combine], 2, 1)
        axis, reverse = eqn.params["axis"], eqn.params["reverse"]
        x = np.asarray(operands[0], dtype=object)
        x = np.flip(x, axis) if reverse else x
        out = ufunc.accumulate(x, axis=axis, dtype=object)
        return [np.flip(out, axis) if reverse else out]

    return rule


SYMBOLIC_RULES: dict[str, Callable[[Walk, Any, list[Any]], list[Any]]] = {
    "select_n": _select_n,
    "integer_pow": _integer_pow,
    "convert_element_type": _convert,
    "dot_general": _dot_general,
    "reduce_sum": _reduction("add"),
    "reduce_prod": _reduction("mul"),
    "reduce_max": _reduction("max"),
    "reduce_min": _reduction("min"),
    "cumsum": _cumulative("add"),
    "cumprod": _cumulative("mul"),
    "cummax": _cumulative("max"),
    "cummin": _cumulative("min"),
}
