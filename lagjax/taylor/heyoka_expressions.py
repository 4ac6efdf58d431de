r"""A JAX vector field as a system of heyoka expressions, read off its jaxpr.

heyoka (Biscani & Izzo 2021) integrates ODEs written in its own expression system by
Taylor's method: it decomposes the right-hand side into elementary operations and
compiles, with LLVM, the recurrences that give each operation's Taylor coefficients
from its operands' (Jorba & Zou 2005). lagjax's derived equations of motion are
already such a sequence of elementary operations — the jaxpr of
`vector_field(t, y, args)` — so the translation is a walk over that jaxpr in which
every value is a NumPy array whose elements are heyoka expressions or numbers:

- the state `y` becomes heyoka variables, `t` becomes `heyoka.time`, and every
  scalar of `args` a runtime parameter `heyoka.par[i]` (a new value of `args` needs
  no new compilation);
- an equation whose operands are all numbers is evaluated by JAX itself, so
  indices, iotas and constant tables keep JAX's exact meaning;
- arithmetic and elementary functions map element by element onto heyoka's, `where`
  and comparisons onto `heyoka.select` and its relational operators (the unselected
  branch never leaks: lagjax's NaN-poisoning `where(singular, nan, x)` stays exact);
- a data-movement primitive (slice, reshape, gather, scatter, concatenate, …) is
  applied by JAX to an array of element indices, and the result picks the elements;
- calls (`jit`, `custom_jvp`, `custom_vjp`, `checkpoint`) are entered, a `scan` of
  fixed length is unrolled, a `while_loop` is unrolled while its condition is a
  number, a `cond` with a numeric index takes its branch and one with a
  state-dependent index becomes a select over all branches.

A branch of a state-dependent `cond` that cannot be translated (lagjax's pivoted-LU
fallback behind its unrolled factorizations) is replaced by NaN: a run that reaches a
state needing it stops as non-finite, never silently wrong; the translation records
which primitive it met (`HeyokaSystem.poisoned`). Any other primitive outside these
rules is refused by name (`UnsupportedPrimitiveError`).

References: F. Biscani & D. Izzo, "Revisiting high-order Taylor methods for
astrodynamics and celestial mechanics", MNRAS 504 (2021) 2614; À. Jorba & M. Zou,
"A software package for the numerical integration of ODEs by means of high-order
Taylor methods", Experimental Mathematics 14 (2005) 99; the JAX documentation,
"Writing custom Jaxpr interpreters in JAX".
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.extend as jex
import jax.numpy as jnp
import numpy as np

from lagjax._linalg.jaxpr_interpreter import evaluate_jaxpr
from lagjax._linalg.marked_solves import MARKED_SOLVE_NAME, marking_solves
from lagjax._linalg.unrolled_ldl import ldl_factor_unrolled, ldl_solve_unrolled
from lagjax.taylor.heyoka_control import CONTROL_RULES
from lagjax.taylor.heyoka_moves import DATA_MOVES, bind, move
from lagjax.taylor.heyoka_rules import (
    SYMBOLIC_RULES,
    UnsupportedPrimitiveError,
    as_expression,
    element_map,
    symbolic,
)
from lagjax.taylor.heyoka_signs import folding_rules

# Calls whose inner jaxpr is evaluated in place, and the parameter that holds it.
INNER_JAXPR = {
    "custom_jvp_call": "call_jaxpr",
    "custom_vjp_call": "call_jaxpr",
    "custom_vjp_call_jaxpr": "fun_jaxpr",
    "custom_vmap_call": "call",
    "remat2": "jaxpr",
    "checkpoint": "jaxpr",
}


@dataclass(frozen=True)
class HeyokaSystem:
    """The ODE system `y' = f(t, y, args)` in heyoka's expressions.

    - `equations`: ((y_i, f_i), ...) as `heyoka.taylor_adaptive` takes them.
    - `num_pars`: how many scalars `args` holds (`heyoka.par[0 … num_pars-1]`).
    - `poisoned`: primitives of state-dependent `cond` branches replaced by NaN.
    - `source`: a digest of the jaxpr the equations were read from (its text,
      constants, state size and `args` signature; `jaxpr_digest`), or "".
    """

    equations: tuple[tuple[Any, Any], ...]
    num_pars: int
    poisoned: tuple[str, ...]
    source: str = ""

    @functools.cached_property
    def key(self) -> _Equations:
        """The right-hand sides as a dictionary key, hashed once."""
        rhs = tuple(rhs for _, rhs in self.equations)
        return _Equations(rhs, self.num_pars, self.source)


class _Equations:
    """Equations as a dictionary key: hashed once by heyoka's hash; equal when
    they are the same expression objects, or read from the same jaxpr (equal
    `source` digests: the translation is deterministic). Never by heyoka's `==`,
    which walks an expression as a tree, not as the graph it is: two
    translations of the 4-link pendulum's equations compared for minutes (each
    shared subexpression walked once per path to it), and lj.simulate beside
    heyoka_integrate on the 8-link chain never finished."""

    def __init__(self, rhs: tuple[Any, ...], num_pars: int, source: str) -> None:
        self.rhs, self.num_pars, self.source = rhs, num_pars, source
        self.hash = hash((rhs, num_pars))

    def __hash__(self) -> int:
        return self.hash

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, _Equations):
            return NotImplemented
        if self.num_pars != other.num_pars or len(self.rhs) != len(other.rhs):
            return False
        if all(a is b for a, b in zip(self.rhs, other.rhs)):
            return True
        return bool(self.source) and self.source == other.source


def import_heyoka() -> Any:
    """heyoka, or an ImportError that says how to install it (an optional peer)."""
    try:
        import heyoka
    except ImportError as error:
        raise ImportError(
            "lagjax's heyoka backend needs the optional package heyoka: "
            "`pip install heyoka` (or `pip install lagjax[heyoka]`)."
        ) from error
    return heyoka


def flatten_args(args: Any) -> np.ndarray:
    """Every scalar of the pytree `args`, in the order of `heyoka.par[i]`."""
    leaves = jax.tree_util.tree_leaves(args)
    if not leaves:
        return np.zeros(0)
    return np.concatenate([np.ravel(np.asarray(leaf, dtype=float)) for leaf in leaves])


def jaxpr_to_heyoka(
    vector_field: Callable[[Any, Any, Any], Any], n: int, args_example: Any = None
) -> HeyokaSystem:
    """Translate `vector_field(t, y, args)` (y of shape (n,), returning shape (n,))
    into heyoka's expressions; `args_example` gives the structure and shapes of
    `args` (its values are not used: each scalar becomes a heyoka parameter).

    Raises `UnsupportedPrimitiveError`, naming the primitive, for a vector field
    that heyoka's expression system cannot express.
    """
    hy = import_heyoka()
    rhs, out_shape, _, poisoned, source = translate_function(
        vector_field, n, args_example
    )
    if out_shape != (n,):
        raise ValueError(
            f"vector_field must return an array of shape ({n},) for a state of shape "
            f"({n},); it returned shape {out_shape}."
        )
    states = state_variables(hy, n)
    num_pars = sum(int(np.size(x)) for x in jax.tree_util.tree_leaves(args_example))
    return HeyokaSystem(tuple(zip(states, rhs)), num_pars, poisoned, source)


def state_variables(hy: Any, n: int) -> list[Any]:
    """The heyoka variables of the state y = (y0, …, y{n-1})."""
    return [hy.make_vars(f"y{i}") for i in range(n)]


def translate_function(
    fn: Callable[[Any, Any, Any], Any], n: int, args_example: Any = None
) -> tuple[list[Any], tuple[int, ...], Any, tuple[str, ...], str]:
    """`fn(t, y, args)` (one array output) as heyoka expressions in the state
    variables, `heyoka.time` and the parameters: (the output's elements as
    expressions, its shape, its dtype, the poisoned primitives met, the digest
    of its jaxpr, `jaxpr_digest`)."""
    hy = import_heyoka()
    with marking_solves():  # the mass-matrix solve as LDLᵀ (`_marked_solve`)
        closed = jax.make_jaxpr(fn)(
            jnp.zeros((), float), jnp.zeros((n,), float), args_example
        )
    if len(closed.out_avals) != 1:
        raise ValueError(
            f"the function translated for heyoka must return one array; it returned "
            f"{len(closed.out_avals)}."
        )
    (out_aval,) = closed.out_avals
    inputs = [_objects([hy.time], ()), _objects(state_variables(hy, n), (n,))]
    offset = 0
    for leaf in jax.tree_util.tree_leaves(args_example):
        size = int(np.size(leaf))
        inputs.append(
            _objects([hy.par[offset + i] for i in range(size)], np.shape(leaf))
        )
        offset += size
    walk = _Walk(hy)
    # Equations on numbers are evaluated now, also inside a caller's `jit`.
    with jax.ensure_compile_time_eval():
        (out,) = walk.evaluate(closed.jaxpr, closed.consts, inputs)
    elements = [as_expression(hy, e) for e in np.asarray(out, dtype=object).ravel()]
    shape = tuple(out_aval.shape)
    digest = jaxpr_digest(closed, n, args_example)
    return elements, shape, out_aval.dtype, tuple(walk.poisoned), digest


def jaxpr_digest(closed: Any, n: int, args_example: Any) -> str:
    """SHA-256 of what a translation reads: the jaxpr's text (primitives,
    parameters, literals), its constants' dtypes, shapes and bytes, the state
    size, the structure and shapes of `args`, and heyoka's version. Equal
    digests, equal expressions (within a process, whose rules do not change); a jaxpr printed
    with a function's address in it (a custom rule) digests anew at each trace,
    which only costs a compilation."""
    leaves, treedef = jax.tree_util.tree_flatten(args_example)
    signature = [(np.shape(x), str(jnp.result_type(x))) for x in leaves]
    digest = hashlib.sha256()
    for part in (str(closed.jaxpr), n, treedef, signature, import_heyoka().__version__):
        digest.update(repr(part).encode())
    for const in closed.consts:
        value = np.asarray(const)
        digest.update(repr((value.dtype.str, value.shape)).encode())
        digest.update(np.ascontiguousarray(value).tobytes())
    return digest.hexdigest()


def _marked_solve(hy: Any, m: np.ndarray, rhs: np.ndarray) -> list[np.ndarray]:
    """A marked solve (`lagjax._linalg.marked_solves`) in expressions: LDLᵀ
    without pivoting, each pivot d used as √d·√d, so that a pivot that is not
    positive (M indefinite or singular) makes the right-hand side NaN and the
    run fails as non-finite instead of following an unstable factorization.
    heyoka has no verdict to carry: the singular flag is False."""

    def positive_or_nan(pivot: Any) -> Any:
        if not isinstance(pivot, hy.expression):
            return pivot if pivot > 0 else np.float64(np.nan)
        root = hy.sqrt(pivot)
        return root * root

    if rhs.ndim != 1:
        raise UnsupportedPrimitiveError(MARKED_SOLVE_NAME, "several right-hand sides")
    n = rhs.shape[0]
    upper = [[m[i, j] for j in range(n)] for i in range(n)]
    factor = ldl_factor_unrolled(upper, guard=positive_or_nan)
    return [_objects(ldl_solve_unrolled(factor, list(rhs)), (n,)), np.asarray(False)]


def _objects(elements: Sequence[Any], shape: Sequence[int]) -> np.ndarray:
    array = np.empty(len(elements), dtype=object)
    array[:] = list(elements)
    return array.reshape(tuple(shape))


class _Walk:
    """One translation: heyoka, its element rules (negations folded as they
    are met, `heyoka_signs`), and the poisoned branches met so far."""

    def __init__(self, hy: Any) -> None:
        self.hy = hy
        self.elementwise = folding_rules(hy)
        self.poisoned: list[str] = []

    def evaluate(self, jaxpr: Any, consts: Sequence[Any], inputs: Sequence[Any]):
        return evaluate_jaxpr(
            jaxpr, consts, inputs, self.rule, literal=np.asarray, const=np.asarray
        )

    def enter(self, inner: Any, operands: Sequence[Any]) -> list[Any]:
        if isinstance(inner, jex.core.ClosedJaxpr):
            return self.evaluate(inner.jaxpr, inner.consts, operands)
        return self.evaluate(inner, [], operands)

    def rule(self, eqn: Any, operands: list[Any]) -> Sequence[Any]:
        name = eqn.primitive.name
        if not any(symbolic(x) for x in operands):
            return bind(eqn, operands)
        if eqn.params.get("name") == MARKED_SOLVE_NAME:
            return _marked_solve(self.hy, *operands)
        if name in INNER_JAXPR:
            return self.enter(eqn.params[INNER_JAXPR[name]], operands)
        if name in CONTROL_RULES:
            return CONTROL_RULES[name](self, eqn, operands)
        if name in DATA_MOVES and not (name == "select_n" and symbolic(operands[0])):
            return move(eqn, operands, DATA_MOVES[name](len(operands)))
        if name in SYMBOLIC_RULES:
            return SYMBOLIC_RULES[name](self, eqn, operands)
        if name in self.elementwise:
            return [element_map(self.elementwise[name], operands)]
        raise UnsupportedPrimitiveError(name)
