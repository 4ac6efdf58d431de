"""Taylor coefficients of a scalar graph with each order as one matrix product.

On the tape (`tape`), order k of an operation's output is its inner Cauchy sums
S = Σ_{j=1}^{k−1} xⱼ yₖ₋ⱼ (orders below k only) plus terms in the current order
of its inputs, with factors that are order-0 values: for a product
cₖ = S + a₀bₖ + aₖb₀, for sin and cos sₖ = S/k + aₖc₀, and so on (the table in
`tape`). Every rule is *linear* in (S, the inputs' k-th coefficients), with
coefficients fixed for the whole step (order-0 values only; the weighted sums
enter as S/k). Composed through the graph, the k-th coefficients of the values
that later sums read are a linear map of the sources

    σₖ = (S/k or S for each sum, yₖ = fₖ₋₁/k, tₖ = [k = 1])

whose matrix A does not depend on k:

    xₖ = A σₖ.

So a step builds A once (the graph's finishing pass on the basis vectors of σ,
one `vmap`), and each order, written out, is two kernels of XLA's CPU backend: a
fused kernel for every inner sum at once (and σₖ) and the product A σₖ. The
sequential pass through the graph — dozens of scalar operations per order, which
XLA splits into many small kernels or recomputes in every consumer — runs once
per step instead of once per order.

What A σₖ produces are *slots*: the first operand of every sum, the second
operand of every sum, the rates, the state (a value may fill several slots), so
the next orders read their operands as contiguous slices, which XLA fuses into
the sums' kernel (a gather by index would be a kernel of its own). Everything
else (affine steps, scalings, the sums' own outputs) lives only inside A. The
cost per order is (sums × k) multiply-adds for the sums and (slots × sources)
for A σₖ: for the double pendulum 17 sums, 4 states, A is 42 × 22.

Two facts of XLA's CPU backend (jax 0.10) shape the code: a vector times a
matrix is rewritten as a multiply-reduce and fused with its producer, so the
sums would be recomputed for every slot (a matrix times a column stays a dot);
and an `optimization_barrier` on σₖ did not stop that fusion (measured: the
compiled program has no barrier left and 2.4× the run time).

In exact arithmetic A σₖ equals the sequential pass; in floating point the sums
are grouped differently (each coefficient of A is a product of order-0 factors,
rounded once), a relative difference of a few ulps, as between any two orders of
summation.

References: Jorba & Zou, Experimental Mathematics 14 (2005), §2 (the
recurrences, linear in the new coefficients); Biscani & Izzo, MNRAS 504 (2021)
(heyoka's decomposition into elementary operations).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .graph import Graph
from .tape import TERMS, finish

# Above this many entries of A, its product per order (O(slots × sources)) may
# outweigh the sequential pass it replaces (O(operations)). Measured: the
# lagjax-derived double pendulum, A 112 × 58, runs 1.3× faster than the tape.
MAX_MATRIX_ENTRIES = 128 * 128


class _Plan(NamedTuple):
    """What A σ produces, in this order: the first operand of every sum, the
    second operand of every sum, the rates f, the state y (value ids, repeats
    allowed); so each order's operands are contiguous slices of one vector."""

    slots: tuple[int, ...]
    weighted: tuple[bool, ...]  # per sum
    first_term: dict[int, int]  # op index -> its first sum


def _plan(graph: Graph) -> _Plan:
    xs, ys, weighted, first = [], [], [], {}
    for index, op in enumerate(graph.ops):
        spec = TERMS.get(type(op.rule), ())
        if op.outs[0] in graph.series and spec:
            first[index] = len(xs)
            for x, y, w in spec:
                xs.append(_operand(op, x))
                ys.append(_operand(op, y))
                weighted.append(w)
    slots = (*xs, *ys, *graph.outputs, *graph.state)
    return _Plan(slots, tuple(weighted), first)


def fits(graph: Graph) -> bool:
    """Whether A is small enough to pay (`MAX_MATRIX_ENTRIES`)."""
    plan = _plan(graph)
    sources = len(plan.weighted) + len(graph.state) + 1
    return len(plan.slots) * sources <= MAX_MATRIX_ENTRIES


def _operand(op: Any, name: str) -> int:
    """The value id of "i0", "i1" (inputs) or "o0", "o1" (outputs) of `op`."""
    return (op.ins if name[0] == "i" else op.outs)[int(name[1])]


def _finishing_map(graph: Graph, values: dict, plan: _Plan, dtype: Any) -> Any:
    """σ ↦ the k-th coefficients of the slots (linear; see module docstring)."""
    n_terms, n_state = len(plan.weighted), len(graph.state)

    def apply(sources: jax.Array) -> jax.Array:
        zero = jnp.zeros((), dtype)
        sums = sources[:n_terms]
        now = dict(zip(graph.state, sources[n_terms : n_terms + n_state]))
        now[graph.inputs[0]] = sources[-1]
        for index, op in enumerate(graph.ops):
            if op.outs[0] not in graph.series:
                continue
            start = plan.first_term.get(index, 0)
            count = len(TERMS.get(type(op.rule), ()))
            zi = [values[i] for i in op.ins]
            current = [
                now[i] if i in graph.series else jnp.zeros_like(z)
                for i, z in zip(op.ins, zi)
            ]
            zo = [values[o] for o in op.outs]
            # k = 1: the weighted sums arrive already divided by k.
            new = finish(op.rule, 1.0, list(sums[start : start + count]),
                         current, zi, zo)  # fmt: skip
            now.update(zip(op.outs, (jnp.asarray(c, dtype) for c in new)))
        return jnp.stack([now.get(v, zero) for v in plan.slots])

    return apply


def order_map_coefficients(
    graph: Graph, values: dict, order: int, dtype: Any
) -> jax.Array:
    """y₀..y_order, shape (order + 1, n), of a scalar graph (one trajectory)
    whose order-0 values are `values`. The orders are written out: each is one
    fused kernel for the sums and one matrix product (the order is static)."""
    plan = _plan(graph)
    n_terms, n_state = len(plan.weighted), len(graph.state)
    n_sources = n_terms + n_state + 1
    basis = np.eye(n_sources, dtype=dtype)  # NumPy: constants XLA folds
    # A[slot, s]: the slot's k-th coefficient per unit of source s.
    matrix = jax.vmap(_finishing_map(graph, values, plan, dtype), out_axes=1)(basis)
    x_of = slice(0, n_terms)
    y_of = slice(n_terms, 2 * n_terms)
    rates_of = slice(2 * n_terms, 2 * n_terms + n_state)
    state_of = slice(2 * n_terms + n_state, None)
    weighted = np.array(plan.weighted, dtype=bool)
    rows = [jnp.stack([jnp.asarray(values[v], dtype) for v in plan.slots])]
    # The state's slots are its sources (yₖ = fₖ₋₁/k) and tₖ is 0 above k = 1:
    # above order 1 neither the state's rows nor the time's column enter the
    # product (a tenth of its multiply-adds for the double pendulum).
    computed = matrix[: len(plan.slots) - n_state, : n_sources - 1]
    for k in range(1, order):
        # Σ_{j=1}^{k−1} xⱼ yₖ₋ⱼ, times j/k where weighted: orders below k only.
        sums = sum(
            (np.where(weighted, j / k, 1.0) * rows[j][x_of] * rows[k - j][y_of]
             for j in range(1, k)),
            start=jnp.zeros(n_terms, dtype),
        )  # fmt: skip
        rates = rows[k - 1][rates_of] / k
        # A matrix times a column: XLA keeps it a dot (a vector-matrix product
        # it rewrites as multiply-reduce and fuses with the sums, which are
        # then recomputed for every slot).
        if k == 1:
            sources = jnp.concatenate([sums, rates, jnp.ones((1,), dtype)])
            rows.append((matrix @ sources[:, None])[:, 0])
            continue
        product = computed @ jnp.concatenate([sums, rates])[:, None]
        rows.append(jnp.concatenate([product[:, 0], rates]))
    states = [row[state_of] for row in rows]  # orders 0..p−1
    return jnp.stack([*states, rows[-1][rates_of] / order])  # y_p = f_{p−1}/p
