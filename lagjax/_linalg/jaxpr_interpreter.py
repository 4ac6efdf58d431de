"""Evaluate a traced function's jaxpr equation by equation, by rules of one's own.

lagjax re-expresses a user's Lagrangian in two ways without asking the user to
write it differently: as arithmetic on scalars for few coordinates (`scalarize`),
and with long cumulative sums as short windows for many (`window_cumsum`). Both
trace the function once to a jaxpr and walk its equations: calls (`jit`, nested
functions) are entered, every other equation goes to the caller's rule. This
module is that walk; the rules stay with their concepts.

References: the JAX documentation, "Writing custom Jaxpr interpreters in JAX".
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import jax.extend as jex

from lagjax._linalg.marked_solves import MARKED_SOLVE_NAME

# Primitives that call a closed jaxpr of their own (`jax.jit` inside the function,
# jnp's functions): evaluated by entering that jaxpr.
CALLS = frozenset({"pjit", "jit", "closed_call"})


def entered(eqn: Any) -> bool:
    """Whether the walk enters `eqn`'s jaxpr: a call, except a marked solve
    (`marked_solves`), which goes to the rule as one equation."""
    return eqn.primitive.name in CALLS and eqn.params.get("name") != MARKED_SOLVE_NAME


Rule = Callable[[Any, list[Any]], Sequence[Any]]


def _unchanged(value: Any) -> Any:
    return value


def evaluate_jaxpr(
    jaxpr: Any,
    consts: Sequence[Any],
    inputs: Sequence[Any],
    rule: Rule,
    *,
    literal: Callable[[Any], Any] = _unchanged,
    const: Callable[[Any], Any] = _unchanged,
) -> list[Any]:
    """The outputs of `jaxpr` at `inputs`, each equation outside `CALLS` given by
    `rule(eqn, operands)` (a sequence, one value per output variable).

    `literal` and `const` convert the jaxpr's literal values and its constants
    into the interpreter's representation of a value (identity by default).
    """
    env: dict[Any, Any] = {}

    def read(atom):
        return literal(atom.val) if isinstance(atom, jex.core.Literal) else env[atom]

    env.update((var, const(value)) for var, value in zip(jaxpr.constvars, consts))
    env.update(zip(jaxpr.invars, inputs))
    for eqn in jaxpr.eqns:
        operands = [read(v) for v in eqn.invars]
        if entered(eqn):
            closed = eqn.params["jaxpr"]
            results = evaluate_jaxpr(
                closed.jaxpr,
                closed.consts,
                operands,
                rule,
                literal=literal,
                const=const,
            )
        else:
            results = rule(eqn, operands)
        env.update(zip(eqn.outvars, results))
    return [read(v) for v in jaxpr.outvars]


def any_equation(jaxpr: Any, test: Callable[[Any], bool]) -> bool:
    """Whether `test(eqn)` holds for an equation of `jaxpr` or of a call in it."""
    for eqn in jaxpr.eqns:
        if entered(eqn):
            if any_equation(eqn.params["jaxpr"].jaxpr, test):
                return True
        elif test(eqn):
            return True
    return False
