r"""Control flow of a vector field's jaxpr in heyoka's expressions.

heyoka's expressions have no loops and no branches, only `heyoka.select` (both
operands are computed, one is taken; the Taylor coefficients are the taken
operand's). So, in the translation (`heyoka_expressions`):

- a `scan` of fixed length is unrolled (`jax.lax.fori_loop` with static bounds is
  one);
- a `while_loop` is unrolled as long as its condition is a number; a condition that
  depends on the state is refused by name;
- a `cond` with a numeric index takes its branch; with a state-dependent index,
  every branch is translated and the index selects among them, element by element.
  A branch that cannot be translated is replaced by NaN for its floating outputs:
  a run that reaches a state needing it stops as non-finite (heyoka's
  `err_nf_state`), never silently wrong, and the primitive met is recorded.

References: F. Biscani & D. Izzo, "Revisiting high-order Taylor methods for
astrodynamics and celestial mechanics", MNRAS 504 (2021) 2614; the JAX
documentation, `jax.lax.cond`, `jax.lax.scan`, `jax.lax.while_loop`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from lagjax.taylor.heyoka_rules import (
    UnsupportedPrimitiveError,
    Walk,
    select_elements,
    symbolic,
)

MAX_UNROLL = 100_000  # iterations of a scan or while_loop unrolled at most


def _cond(walk: Walk, eqn: Any, operands: list[Any]) -> list[Any]:
    """The taken branch for a numeric index; a select over the branches for a
    state-dependent one, an untranslatable branch replaced by NaN (recorded)."""
    index, *inputs = operands
    branches = eqn.params["branches"]
    if not symbolic(index):
        taken = int(np.clip(int(index), 0, len(branches) - 1))
        return walk.enter(branches[taken], inputs)
    outputs, failures = [], []
    for branch in branches:
        try:
            outputs.append(walk.enter(branch, inputs))
        except UnsupportedPrimitiveError as error:
            failures.append(error)
            outputs.append([_poison(aval) for aval in branch.out_avals])
    if len(failures) == len(branches):
        raise failures[0]
    walk.poisoned.extend(error.primitive for error in failures)
    return [select_elements(walk.hy, index, cases) for cases in zip(*outputs)]


def _poison(aval: Any) -> np.ndarray:
    """A branch's output where it cannot be translated: NaN for floats (a run that
    takes the branch stops as non-finite); zeros for flags and integers."""
    fill = np.nan if np.issubdtype(aval.dtype, np.floating) else 0
    return np.full(aval.shape, fill, dtype=aval.dtype)


def _scan(walk: Walk, eqn: Any, operands: list[Any]) -> list[Any]:
    """A scan of fixed length, unrolled."""
    p = eqn.params
    length, n_consts, n_carry = p["length"], p["num_consts"], p["num_carry"]
    if length > MAX_UNROLL:
        raise UnsupportedPrimitiveError("scan", f"length {length} > {MAX_UNROLL}")
    consts, carry = operands[:n_consts], operands[n_consts : n_consts + n_carry]
    xs = operands[n_consts + n_carry :]
    steps = range(length - 1, -1, -1) if p["reverse"] else range(length)
    ys: list[list[Any]] = []
    for i in steps:
        outs = walk.enter(p["jaxpr"], [*consts, *carry, *[x[i] for x in xs]])
        carry, y = outs[:n_carry], outs[n_carry:]
        ys.append(y)
    ys = ys[::-1] if p["reverse"] else ys
    stacked = [
        _stack([y[j] for y in ys], aval) for j, aval in enumerate(eqn.outvars[n_carry:])
    ]
    return [*carry, *stacked]


def _stack(values: list[Any], var: Any) -> np.ndarray:
    if not values:
        return np.zeros(var.aval.shape, var.aval.dtype)
    if any(symbolic(v) for v in values):
        return np.stack([np.asarray(v, dtype=object) for v in values])
    return np.stack(values)


def _while(walk: Walk, eqn: Any, operands: list[Any]) -> list[Any]:
    """A while_loop unrolled as long as its condition does not depend on the state."""
    p = eqn.params
    n_cond, n_body = p["cond_nconsts"], p["body_nconsts"]
    cond_consts, body_consts = operands[:n_cond], operands[n_cond : n_cond + n_body]
    carry = operands[n_cond + n_body :]
    for _ in range(MAX_UNROLL):
        (go,) = walk.enter(p["cond_jaxpr"], [*cond_consts, *carry])
        if symbolic(go):
            raise UnsupportedPrimitiveError(
                "while", "a loop whose condition depends on the state"
            )
        if not bool(go):
            return carry
        carry = walk.enter(p["body_jaxpr"], [*body_consts, *carry])
    raise UnsupportedPrimitiveError("while", f"more than {MAX_UNROLL} iterations")


CONTROL_RULES: dict[str, Callable[[Walk, Any, list[Any]], list[Any]]] = {
    "cond": _cond,
    "scan": _scan,
    "while": _while,
}
