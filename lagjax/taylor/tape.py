"""Taylor coefficients of a scalar graph on a tape: every convolution of an order
in one vector operation, the rest a short chain of scalar updates.

In every recurrence (`recurrences`) the k-th coefficient of an operation's output
is a Cauchy sum plus terms in the current order. Splitting each sum

    (a ⋆ b)ₖ = a₀bₖ + aₖb₀ + Σ_{j=1}^{k−1} aⱼ bₖ₋ⱼ,

the inner sums use only orders below k, which are all known when order k begins.
So each order is two passes:

1. every inner sum of every operation at once. The tape T (orders × slots ×
   batch, stored flat as orders × (slots · batch)) holds in row j the j-th
   coefficients of its *slots*: the first operand of every term, then the second
   operand of every term, then the rates f (a value may fill several slots), so
   the operands of all terms are two contiguous slabs X and Y and

       S = Σ_{j=1}^{k−1} T[j, X] ⊙ T[k − j, Y],

   one vector multiply-add per j over every term and member at once. A
   j-weighted term's first slot holds j xⱼ instead of xⱼ (nothing else reads
   it), so no sum needs weights. Each order k is a branch of its own
   (`lax.switch` on k) whose slices are static: exact lengths, no dynamic index;
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

then row k of the tape (the slots' k-th coefficients) is written at once. Per
order the program is a few kernels, whatever the number of operations; with a
batch on the last axis each is one vector operation over the members. Only what
later orders read is on the tape, the intermediate values of the second pass
are not.

Why this form (XLA CPU, jax 0.10; double pendulum ×1024 to t = 10 at tol 1e-12,
tiles of 32, one pinned core, each change against the previous one interleaved
in one run, ratios to heyoka's batch mode): the earlier tape (every series value
× 2p rows, the sums one gather-multiply-reduce over a window of 2p − 1 orders)
5.07×; slots and a slab product per j over all p − 2 values of j, the second
operand dynamically indexed, 4.1×; a branch per order with static slices and
exact lengths, 2.2×; the weights folded into the tape, 1.9×. Reductions over the
order axis compiled to scalar loops and dynamic slices of a slab to scalar code
with index arithmetic; a product of static contiguous slabs is vectorized. XLA
vectorizes such a slab when it is long (≥ 64 elements), but fully unrolls and
leaves scalar an axis of 32: the slabs are flat, never (slots, 32).

References: Jorba & Zou, Experimental Mathematics 14 (2005), §2 (the
recurrences); Biscani & Izzo, MNRAS 504 (2021) (heyoka's decomposition into
elementary operations and its batch mode).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import lagjax.taylor.recurrences as rec

from .graph_values import Graph

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
    """The tape's slots, in this order: the first operand of every term, the
    second operand of every term, the rates f (value ids, repeats allowed), so
    that each order's operands are two contiguous slabs."""

    slots: tuple[int, ...]
    weighted: tuple[bool, ...]  # per term
    first_term: dict[int, int]  # op index -> its first term


def _name(op: Any, operand: str) -> int:
    """The value id of "i0", "i1" (inputs) or "o0", "o1" (outputs) of `op`."""
    return (op.ins if operand[0] == "i" else op.outs)[int(operand[1])]


def _layout(graph: Graph) -> _Layout:
    xs, ys, weighted, first = [], [], [], {}
    for index, op in enumerate(graph.ops):
        spec = TERMS.get(type(op.rule), ())
        if op.outs[0] in graph.series and spec:
            first[index] = len(xs)
            for x, y, w in spec:
                xs.append(_name(op, x))
                ys.append(_name(op, y))
                weighted.append(w)
    return _Layout((*xs, *ys, *graph.outputs), tuple(weighted), first)


def _inner_sums(
    tape: jax.Array, k: Any, layout: _Layout, order: int, width: int
) -> jax.Array:
    """Σ_{j=1}^{k−1} xⱼ yₖ₋ⱼ (j-weighted where asked) for every term at once,
    flat: (terms × width,). Each k (1 ≤ k ≤ order − 1) is a branch of its own with
    static slices: k − 1 multiply-adds of contiguous slabs, exact lengths (the
    first operand of a j-weighted term is stored as j xⱼ)."""
    size = len(layout.weighted) * width

    def at(k: int):
        def sums(tape: jax.Array) -> jax.Array:
            total = jnp.zeros((size,), tape.dtype)
            for j in range(1, k):
                total = total + tape[j, :size] * tape[k - j, size : 2 * size]
            return total

        return sums

    branches = [at(k) for k in range(1, max(order, 2))]
    return jax.lax.switch(k - 1, branches, tape)


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


def tape_shape(graph: Graph, order: int, shape: tuple) -> tuple[int, int]:
    """The tape's shape for `graph` at `order` with values of shape `shape`:
    (order + 1, slots × width)."""
    return (order + 1, len(_layout(graph).slots) * math.prod(shape))


def tape_coefficients(
    graph: Graph,
    values: dict,
    order: int,
    shape: tuple,
    dtype: Any,
    tape: jax.Array | None = None,
) -> Any:
    """y₀..y_order, shape (order + 1, n, *shape), of a scalar graph whose order-0
    values (every input and operation, each of shape `shape`: () or (B,)) are
    `values`. The tape is (order + 1, slots × width), width = B (1 for one
    trajectory): row j holds the slots' j-th coefficients, one slot after
    another, so an order is one contiguous write and the sums read contiguous
    slabs.

    `tape`: the buffer to work in (shape `tape_shape`), e.g. the previous step's;
    the result is then (coefficients, tape). Its contents do not matter: every
    row an order reads was written earlier in the same call (row 0 first). A
    loop of steps that carries it spares a fresh, zeroed tape per step (double
    pendulum ×1024 to t = 10 at tol 1e-12, tiles of 32: XLA wrote 155 kB of
    zeros per step with `memset`, 7 % of the run; carried, 0.92× the time,
    interleaved in one run, core 1)."""
    layout = _layout(graph)
    terms, width = len(layout.weighted), math.prod(shape)
    full = lambda x: jnp.broadcast_to(x, shape)
    real = lambda x: full(jnp.asarray(x, dtype))
    flat_row = lambda xs: jnp.concatenate([jnp.ravel(x) for x in xs])
    zero_row = flat_row([real(values[v]) for v in layout.slots])
    given = tape is not None
    if tape is None:
        tape = jnp.zeros(tape_shape(graph, order, shape), dtype)
    elif tape.shape != tape_shape(graph, order, shape) or tape.dtype != dtype:
        raise ValueError(
            f"lagjax.taylor: the tape given has shape {tape.shape} {tape.dtype}; "
            f"this graph at order {order} needs {tape_shape(graph, order, shape)} "
            f"{jnp.dtype(dtype)} (tape_shape)"
        )
    start = tape.at[0].set(zero_row)

    def one_order(k: Any, tape: jax.Array) -> jax.Array:
        sums = _inner_sums(tape, k, layout, order, width).reshape((terms, *shape))
        kf = jnp.asarray(k, dtype)
        # yₖ = fₖ₋₁/k, from the rates' previous order (the tape's last n slots).
        rates = jax.lax.dynamic_index_in_dim(tape, k - 1, keepdims=False)
        rates = rates[2 * terms * width :].reshape((-1, *shape)) / kf
        now = dict(zip(graph.state, rates))
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
        # A j-weighted term's first slot holds k xₖ: its sums need no weights.
        weights = [kf if w else None for w in layout.weighted]
        row = [now.get(v, real(0.0)) for v in layout.slots]
        row[:terms] = [x if w is None else w * x for x, w in zip(row, weights)]
        row = flat_row(row)
        return jax.lax.dynamic_update_index_in_dim(tape, row, k, axis=0)

    filled = jax.lax.fori_loop(1, max(order, 1), one_order, start)
    state = jnp.stack([real(values[y]) for y in graph.state])
    divisors = np.arange(1, order + 1).reshape((-1,) + (1,) * (1 + len(shape)))
    # y_k = f_{k−1}/k for k = 1..order, from the rates' rows 0..order−1.
    rates = filled[:order, 2 * terms * width :].reshape((order, -1, *shape))
    coefficients = jnp.concatenate([state[None], rates / divisors.astype(dtype)])
    return (coefficients, filled) if given else coefficients
