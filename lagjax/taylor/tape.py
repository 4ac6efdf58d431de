"""Taylor coefficients of a scalar graph on a tape: every convolution of an order
in one vector operation, the rest a short chain of scalar updates.

In every recurrence (`recurrences`) the k-th coefficient of an operation's output
is a Cauchy sum plus terms in the current order. Splitting each sum

    (a ⋆ b)ₖ = a₀bₖ + aₖb₀ + Σ_{j=1}^{k−1} aⱼ bₖ₋ⱼ,

the inner sums use only orders below k, which are all known when order k begins.
So each order is two passes:

1. every inner sum of every operation at once: the series live on one tape
   T (values × 2P × batch), coefficient j of a value in column P + j and zeros
   in columns 0..P−1, so bₖ₋ⱼ for j = 1..P−1 is one reversed window
   T[b, k+1 : k+P]; the sums are one gather, multiply and reduce over all terms;
2. the operations in order, each O(1) from the inner sums, the order-0 values
   and the current order's coefficients of its inputs (below, j-weighted sums
   are marked (j·)):

| operation        | inner sums                     | k-th coefficient                         |
|------------------|--------------------------------|------------------------------------------|
| c = a·b          | a⋆b                            | S + a₀bₖ + aₖb₀                          |
| c = a/b          | b⋆c                            | (aₖ − S − bₖc₀)/b₀                        |
| c = exp a        | (j·a)⋆c                        | (S + k aₖc₀)/k  (+ aₖ for expm1)         |
| c = log a        | (j·c)⋆a                        | (aₖ − S/k)/a₀  (a₀ + 1 for log1p)         |
| c = a^α          | c⋆a, (j·c)⋆a                   | (α(c₀aₖ + S₁) − (α+1)S₂/k)/a₀             |
| c = √a           | c⋆c                            | (aₖ − S)/(2c₀)                            |
| s, c = sin, cos  | (j·a)⋆c, (j·a)⋆s               | (S₁ + k aₖc₀)/k, −(S₂ + k aₖs₀)/k         |
| t, u = tan, 1±t² | (j·a)⋆u, t⋆t                   | (S₁ + k aₖu₀)/k, ±(S₂ + 2t₀tₖ)            |

then the column k of the tape is written at once. Per order the program is a
few kernels, whatever the number of operations; with a batch on the last axis
each is one vector operation over the members. The inner sums run over P − 1
terms (those above k are zeros on the tape), twice the multiplications of exact
sums in exchange for one kernel.

References: Jorba & Zou, Experimental Mathematics 14 (2005), §2 (the
recurrences); Biscani & Izzo, MNRAS 504 (2021) (heyoka's decomposition into
elementary operations and its batch mode).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

import lagjax.taylor.recurrences as rec

from .graph import Graph

# Which sums each rule needs: (x, y, j-weighted) with x, y naming an input ("i0",
# "i1") or an output ("o0", "o1") of the operation; the sum is Σ_{j=1}^{k−1} xⱼ yₖ₋ⱼ.
TERMS: dict[type, tuple] = {
    rec.Product: (("i0", "i1", False),),
    rec.Quotient: (("i1", "o0", False),),
    rec.Exp: (("i0", "o0", True),),
    rec.Log: (("o0", "i0", True),),
    rec.Power: (("o0", "i0", False), ("o0", "i0", True)),
    rec.Sqrt: (("o0", "o0", False),),
    rec.SinCos: (("i0", "o1", True), ("i0", "o0", True)),
    rec.TanLike: (("i0", "o1", True), ("o0", "o0", False)),
}
_LINEAR = (rec.Affine, rec.Scale, rec.Fixed, rec.Branch)


def supports(graph: Graph) -> bool:
    """Whether the tape can run `graph`: a scalar graph of known rules (products
    of scalars only)."""
    for op in graph.ops:
        if op.outs[0] not in graph.series:
            continue
        if not isinstance(op.rule, (*_LINEAR, *TERMS)):
            return False
        if isinstance(op.rule, rec.Product) and op.rule.primitive.name != "mul":
            return False
    return graph.scalar


class _Layout(NamedTuple):
    rows: dict[int, int]  # series value -> tape row; t first, then the state
    terms: tuple[tuple[int, int, bool], ...]  # (row x, row y, weighted)
    first_term: dict[int, int]  # op index -> its first term


def _name(op: Any, operand: str) -> int:
    """The value id of "i0", "i1" (inputs) or "o0", "o1" (outputs) of `op`."""
    return (op.ins if operand[0] == "i" else op.outs)[int(operand[1])]


def _layout(graph: Graph) -> _Layout:
    ordered = [graph.inputs[0], *graph.state, *graph.outputs]
    ordered += [o for op in graph.ops for o in op.outs if o in graph.series]
    rows = {v: r for r, v in enumerate(dict.fromkeys(ordered))}
    terms, first = [], {}
    for index, op in enumerate(graph.ops):
        spec = TERMS.get(type(op.rule), ())
        if op.outs[0] in graph.series and spec:
            first[index] = len(terms)
            for x, y, weighted in spec:
                terms.append((rows[_name(op, x)], rows[_name(op, y)], weighted))
    return _Layout(rows, tuple(terms), first)


def _inner_sums(tape: jax.Array, k: Any, layout: _Layout, size: int) -> jax.Array:
    """Σ_{j=1}^{k−1} xⱼ yₖ₋ⱼ (j-weighted where asked) for every term: (terms, *batch)."""
    shape = (-1,) + (1,) * (tape.ndim - 2)
    j = jnp.arange(1, size, dtype=tape.dtype).reshape(shape)
    keep = j < k  # rows written ahead (time) are kept out
    # yₖ₋ⱼ for j = 1..P−1 sits in the tape's rows P + k − 1 down to k + 1.
    window = jnp.flip(jax.lax.dynamic_slice_in_dim(tape, k + 1, size - 1, axis=0), 0)
    sums = []
    for x, y, weighted in layout.terms:
        weights = jnp.where(keep, j if weighted else 1.0, 0.0)
        sums.append(jnp.sum(weights * tape[size + 1 :, x] * window[:, y], axis=0))
    return jnp.stack(sums)


def finish(rule: Any, k: Any, s: list, now: list, zi: list, zo: list) -> tuple:
    """The outputs' k-th coefficients from the inner sums `s`, the inputs' k-th
    coefficients `now` and the order-0 inputs `zi` and outputs `zo`."""
    kind = type(rule)
    if kind is rec.Product:
        return (s[0] + zi[0] * now[1] + now[0] * zi[1],)
    if kind is rec.Quotient:
        return ((now[0] - s[0] - now[1] * zo[0]) / zi[1],)
    if kind is rec.Exp:
        extra = now[0] if rule.primitive.name == "expm1" else 0.0
        return ((s[0] + k * now[0] * zo[0]) / k + extra,)
    if kind is rec.Log:
        a0 = zi[0] + 1 if rule.primitive.name == "log1p" else zi[0]
        return ((now[0] - s[0] / k) / a0,)
    if kind is rec.Power:
        alpha = zi[1]
        return ((alpha * (zo[0] * now[0] + s[0]) - (alpha + 1) * s[1] / k) / zi[0],)
    if kind is rec.Sqrt:
        return ((now[0] - s[0]) / (2 * zo[0]),)
    if kind is rec.SinCos:
        return ((s[0] + k * now[0] * zo[1]) / k, -(s[1] + k * now[0] * zo[0]) / k)
    if kind is rec.TanLike:
        tk = (s[0] + k * now[0] * zo[1]) / k
        uk = s[1] + 2 * zo[0] * tk
        return (tk, -uk if rule.hyperbolic else uk)
    return _linear(rule, now, zi, zo)


def _linear(rule: Any, now: list, zi: list, zo: list) -> tuple:
    """Affine, Scale, Fixed and Branch rules need no sums."""
    if isinstance(rule, rec.Fixed):
        return tuple(jnp.zeros_like(z) for z in zo)
    if isinstance(rule, rec.Scale):
        return rule._bind(*[n if s else z for n, z, s in zip(now, zi, rule.series)])
    if isinstance(rule, rec.Affine):
        fixed = [rec.coefficient(z, 0, False) for z in zi]
        return rule._bind(*[n if s else f for n, f, s in zip(now, fixed, rule.series)])
    name = rule.primitive.name  # Branch: the side the order-0 values choose
    if name == "abs":
        return (jnp.where(zi[0] >= 0, now[0], -now[0]),)
    first = zi[0] >= zi[1] if name == "max" else zi[0] <= zi[1]
    return (jnp.where(first, now[0], now[1]),)


def tape_coefficients(
    graph: Graph, values: dict, order: int, shape: tuple, dtype: Any
) -> jax.Array:
    """y₀..y_order, shape (order + 1, n, *shape), of a scalar graph whose order-0
    values (every input and operation, each of shape `shape`: () or (B,)) are
    `values`. The tape is (2P, values, *shape): row P + j holds the j-th
    coefficients, so an order is one contiguous write."""
    layout, size = _layout(graph), order + 1
    full = lambda x: jnp.broadcast_to(x, shape)
    real = lambda x: full(jnp.asarray(x, dtype))
    out_rows = jnp.array([layout.rows[r] for r in graph.outputs])
    zero_row = jnp.stack([real(values[v]) for v in layout.rows])
    tape = jnp.zeros((2 * size, len(layout.rows), *shape), dtype).at[size].set(zero_row)

    def one_order(k: Any, tape: jax.Array) -> jax.Array:
        sums = _inner_sums(tape, k, layout, size) if layout.terms else tape[0, :0]
        kf = jnp.asarray(k, dtype)
        # yₖ = fₖ₋₁/k, from the rates' previous order (all on the tape).
        rates = jax.lax.dynamic_index_in_dim(tape, size + k - 1, keepdims=False)
        now = dict(zip(graph.state, rates[out_rows] / kf))
        now[graph.inputs[0]] = jnp.where(k == 1, real(1.0), real(0.0))
        for index, op in enumerate(graph.ops):
            if op.outs[0] not in graph.series:
                continue
            start = layout.first_term.get(index, 0)
            count = len(TERMS.get(type(op.rule), ()))
            zi = [full(values[i]) for i in op.ins]
            current = [
                now[i] if i in graph.series else jnp.zeros_like(z)
                for i, z in zip(op.ins, zi)
            ]
            zo = [full(values[o]) for o in op.outs]
            new = finish(op.rule, kf, [sums[start + i] for i in range(count)],
                          current, zi, zo)  # fmt: skip
            now.update(zip(op.outs, (real(c) for c in new)))
        row = jnp.stack([now.get(v, real(0.0)) for v in layout.rows])
        return jax.lax.dynamic_update_index_in_dim(tape, row, size + k, axis=0)

    tape = jax.lax.fori_loop(1, max(order, 1), one_order, tape)
    state_rows = jnp.array([layout.rows[y] for y in graph.state])
    below = tape[size : 2 * size - 1, state_rows]  # orders 0..p−1
    last = tape[2 * size - 2, out_rows] / order  # y_p = f_{p−1}/p
    return jnp.concatenate([below, last[None]])
