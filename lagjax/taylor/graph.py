"""The vector field as a graph of operations with Taylor rules, read off its jaxpr.

`jax.make_jaxpr(f)(t, y, *args)` lists f's elementary operations. Lowering walks
that list once, at trace time, and keeps for each operation the rule that gives
its outputs' Taylor coefficients (`recurrences`). On the way it:

- marks each value *series* (it varies along the solution: it depends on t or y
  through float arithmetic) or *fixed* within a step (parameters, constants,
  comparisons and integer arithmetic, evaluated once from the order-0 values);
- enters calls (`jit`, `custom_jvp`, `custom_vjp`, `checkpoint`) and evaluates
  their inner jaxpr in place;
- merges repeated operations on the same inputs (common subexpressions: a derived
  Euler–Lagrange jaxpr computes cos(θ₁ − θ₂) many times over), fuses sin and cos
  of one argument into one coupled rule, drops multiplications by a literal 1 and
  additions of a literal 0, writes xⁿ as products (exact through x = 0), and drops
  every operation the output does not need.

The cost of a Taylor step is dominated by the series × series products and the
nonlinear rules, O(p²) each; `Graph.census` counts them.

References: the JAX documentation, "Writing custom Jaxpr interpreters in JAX";
Jorba & Zou (2005) and Biscani & Izzo (2021) on the decomposition of f into
elementary operations.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.extend as jex
import jax.numpy as jnp

import lagjax.taylor.recurrences as rec
from lagjax._linalg.marked_solves import MARKED_SOLVE_NAME

from .graph_signs import fold, foldable, rewrite
from .graph_values import (
    Builder,
    Graph,
    Op,
    frozen_params,
    inner_jaxpr,
    is_float,
    primitive_params,
)

CALLS = frozenset(
    {"pjit", "jit", "closed_call", "core_call", "remat", "checkpoint"}
    | {"custom_jvp_call", "custom_vjp_call", "custom_vjp_call_jaxpr"}
)
AFFINE = frozenset(
    {"add", "add_any", "sub", "neg", "concatenate", "pad", "select_n", "reshape"}
    | {"broadcast_in_dim", "squeeze", "expand_dims", "slice", "dynamic_slice"}
    | {"dynamic_update_slice", "gather", "transpose", "reduce_sum", "copy", "copy_p"}
    | {"convert_element_type", "rev", "cumsum", "stack", "split", "unstack", "real"}
)
PIECEWISE_CONSTANT = frozenset({"sign", "floor", "ceil", "round", "stop_gradient"})
BRANCHES = frozenset({"abs", "max", "min"})


def _integer_power(builder: Builder, x: int, n: int, aval: Any) -> int:
    """xⁿ by repeated squaring: products stay exact through x = 0."""
    if n == 0:
        return builder.constant(jnp.ones(aval.shape, aval.dtype))
    if n < 0:
        one = builder.constant(jnp.ones(aval.shape, aval.dtype))
        return builder.primitive(
            "div", (one, _integer_power(builder, x, -n, aval)), aval
        )
    result, base = None, x
    while n:
        if n & 1:
            result = (
                base
                if result is None
                else builder.primitive("mul", (result, base), aval)
            )
        n >>= 1
        if n:
            base = builder.primitive("mul", (base, base), aval)
    assert result is not None  # n ≥ 1: at least one bit set
    return result


def _series_rule(builder: Builder, eqn: Any, ins: list[int]) -> tuple[int, ...]:
    """Lower one operation with a series input to its rule."""
    name, prim, params = eqn.primitive.name, eqn.primitive, primitive_params(eqn)
    flags = builder.flags(ins)
    avals = [v.aval for v in eqn.outvars]
    key = (name, tuple(ins), frozen_params(params))
    key = None if key[2] is None else key
    if name == "mul" or name == "dot_general":
        one = [i for i, f in zip(ins, flags) if not f and builder.constant_is(i, 1.0)]
        if (
            name == "mul"
            and one
            and avals[0].shape == builder.avals[ins[1 - ins.index(one[0])]].shape
        ):
            return (ins[1 - ins.index(one[0])],)
    signed = rewrite(builder.signs, name, ins, flags, avals)
    if signed is not None:
        return signed
    if name == "mul" or name == "dot_general":
        rule = (
            rec.Product(primitive=prim, params=params, series=flags)
            if all(flags)
            else rec.Scale(primitive=prim, params=params, series=flags)
        )
    elif name == "div":
        rule = (
            rec.Scale(primitive=prim, params=params, series=flags)
            if not flags[1]
            else rec.Quotient(primitive=prim, params=params, series=flags)
        )
    elif name in ("add", "sub") and not flags[1] and builder.constant_is(ins[1], 0.0):
        return (
            (ins[0],)
            if avals[0].shape == builder.avals[ins[0]].shape
            else _affine(builder, eqn, ins, key)
        )
    elif name == "add" and not flags[0] and builder.constant_is(ins[0], 0.0):
        return (
            (ins[1],)
            if avals[0].shape == builder.avals[ins[1]].shape
            else _affine(builder, eqn, ins, key)
        )
    elif name in AFFINE:
        return _affine(builder, eqn, ins, key)
    elif name == "integer_pow":
        return (_integer_power(builder, ins[0], params["y"], avals[0]),)
    elif name == "square":
        return (builder.primitive("mul", (ins[0], ins[0]), avals[0]),)
    elif name in ("sin", "cos"):
        pair = builder.emit(
            rec.SinCos(flags), ins, avals * 2, True, key=("sincos", tuple(ins))
        )
        return (pair[0],) if name == "sin" else (pair[1],)
    elif name in ("tan", "tanh"):
        pair = builder.emit(
            rec.TanLike(hyperbolic=name == "tanh", series=flags),
            ins,
            avals * 2,
            True,
            key=(name, tuple(ins)),
        )
        return (pair[0],)
    elif name in ("exp", "expm1"):
        rule = rec.Exp(primitive=prim, params=params, series=flags)
    elif name in ("log", "log1p"):
        rule = rec.Log(primitive=prim, params=params, series=flags)
    elif name == "sqrt":
        rule = rec.Sqrt(flags)
    elif name in ("rsqrt", "cbrt") or (name == "pow" and not flags[1]):
        alpha = (
            ins[1]
            if name == "pow"
            else builder.constant(-0.5 if name == "rsqrt" else 1 / 3)
        )
        return builder.emit(
            rec.Power((True, False)),
            (ins[0], alpha),
            avals,
            True,
            key=("pow", (ins[0], alpha)),
        )
    elif name in BRANCHES:
        rule = rec.Branch(primitive=prim, params=params, series=flags)
    elif name in PIECEWISE_CONSTANT:
        return builder.emit(
            rec.Fixed(primitive=prim, params=params, series=flags), ins, avals, False
        )
    else:
        raise NotImplementedError(
            f"lagjax.Taylor has no Taylor-coefficient rule for the primitive {name!r} "
            "(applied to a value that varies along the solution)"
        )
    return builder.emit(rule, ins, avals, True, key=key)


def _affine(builder: Builder, eqn: Any, ins: list[int], key: Any) -> tuple[int, ...]:
    rule = rec.Affine(
        primitive=eqn.primitive, params=primitive_params(eqn), series=builder.flags(ins)
    )
    avals = [v.aval for v in eqn.outvars]
    return builder.emit(rule, ins, avals, True, key=key)


def _walk(
    builder: Builder, jaxpr: Any, consts: list[int], inputs: list[int]
) -> list[int]:
    env: dict[Any, int] = dict(zip(jaxpr.constvars, consts))
    env.update(zip(jaxpr.invars, inputs))

    def read(atom: Any) -> int:
        if isinstance(atom, jex.core.Literal):
            return builder.constant(atom.val)
        return env[atom]

    for eqn in jaxpr.eqns:
        ins = [read(v) for v in eqn.invars]
        if eqn.params.get("name") == MARKED_SOLVE_NAME and any(builder.flags(ins)):
            outs = _lower_marked_solve(builder, eqn, ins)
        elif eqn.primitive.name in CALLS:
            inner, consts = inner_jaxpr(eqn)
            const_ids = [builder.constant(c) for c in consts]
            outs = _walk(builder, inner, const_ids, ins)
        elif eqn.primitive.name == "cond" and any(builder.flags(ins[1:])):
            outs = _lower_cond(builder, eqn, ins)
        elif any(builder.flags(ins)) and any(is_float(v.aval) for v in eqn.outvars):
            outs = _series_rule(builder, eqn, ins)
        elif foldable(eqn, ins, builder.constants):
            values = fold(eqn, [builder.constants[i] for i in ins])
            outs = tuple(builder.constant(value) for value in values)
        else:
            rule = rec.Fixed(
                primitive=eqn.primitive,
                params=primitive_params(eqn),
                series=builder.flags(ins),
            )
            outs = builder.emit(rule, ins, [v.aval for v in eqn.outvars], False)
        env.update(zip(eqn.outvars, outs))
    return [read(v) for v in jaxpr.outvars]


def _lower_marked_solve(builder: Builder, eqn: Any, ins: list[int]) -> list[int]:
    """A marked solve (`lagjax._linalg.marked_solves`): x by its own recurrence
    (`LinearSolve`), the singular flag once per step from the order-0 values."""
    params, flags = primitive_params(eqn), builder.flags(ins)
    x_aval, flag_aval = (v.aval for v in eqn.outvars)
    rule = rec.LinearSolve(primitive=eqn.primitive, params=params, series=flags)
    (x,) = builder.emit(rule, ins, [x_aval], True)
    verdict = rec.Fixed(primitive=eqn.primitive, params=params, series=flags)
    _, singular = builder.emit(verdict, ins, [x_aval, flag_aval], False)
    return [x, singular]


def _lower_cond(builder: Builder, eqn: Any, ins: list[int]) -> list[int]:
    """`lax.cond`/`lax.switch` on series operands: every branch in place, each
    output the branch that the order-0 index selects (`select_n`, like `Branch`:
    the step keeps the side where it starts). A branch with a primitive that has
    no Taylor rule (a pivoted LU fallback written as loops) is lowered to NaN:
    a step that starts in it fails as non-finite instead of returning a number."""
    index, operands = ins[0], ins[1:]
    branches, first_error = [], None
    for branch in eqn.params["branches"]:
        const_ids = [builder.constant(c) for c in branch.consts]
        try:
            branches.append(_walk(builder, branch.jaxpr, const_ids, operands))
        except NotImplementedError as error:
            first_error = first_error or error
            branches.append(None)
    if all(outs is None for outs in branches):
        assert first_error is not None
        raise first_error
    outs = []
    for position, var in enumerate(eqn.outvars):
        aval = var.aval
        poison = jnp.full(aval.shape, jnp.nan if is_float(aval) else 0, aval.dtype)
        cases = [
            builder.constant(poison) if taken is None else taken[position]
            for taken in branches
        ]
        rule = rec.Affine(
            primitive=jax.lax.select_n_p,
            params={},
            series=builder.flags((index, *cases)),
        )
        series = is_float(aval) and any(builder.flags(cases))
        (out,) = builder.emit(
            rule
            if series
            else rec.Fixed(primitive=jax.lax.select_n_p, params={}, series=rule.series),
            (index, *cases),
            [aval],
            series,
        )
        outs.append(out)
    return outs


def _needed(ops: list[Op], outputs: tuple[int, ...]) -> tuple[Op, ...]:
    needed, kept = set(outputs), []
    for op in reversed(ops):
        if needed.intersection(op.outs):
            kept.append(op)
            needed.update(op.ins)
    return tuple(reversed(kept))


def lower(closed_jaxpr: Any, state_size: int | None = None) -> Graph:
    """The graph of `closed_jaxpr`, whose inputs are (t, y, *arg leaves) and
    whose one output is dy/dt; t and y are the series inputs. With `state_size`
    n, a scalar graph: the inputs are (t, y₀, …, yₙ₋₁, *arg scalars) and the n
    outputs the elements of dy/dt."""
    jaxpr = closed_jaxpr.jaxpr
    scalar = state_size is not None
    if not scalar and len(jaxpr.outvars) != 1:
        raise TypeError("lagjax.Taylor: the vector field must return one flat array")
    series_inputs = 1 + (state_size if scalar else 1)
    builder = Builder()
    const_ids = [builder.constant(c) for c in closed_jaxpr.consts]
    inputs = [
        builder.new(v.aval, series=position < series_inputs)
        for position, v in enumerate(jaxpr.invars)
    ]
    outputs = tuple(_walk(builder, jaxpr, const_ids, inputs))
    return Graph(
        ops=_needed(builder.ops, outputs),
        series=frozenset(builder.series),
        constants=builder.constants,
        avals=builder.avals,
        inputs=tuple(inputs),
        state=tuple(inputs[1:series_inputs]),
        outputs=outputs,
        scalar=scalar,
    )
