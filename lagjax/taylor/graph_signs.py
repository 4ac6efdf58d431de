"""Constants and signs folded while the vector field's graph is lowered.

A derived Euler–Lagrange jaxpr carries arithmetic that a Taylor step would pay
for at every order: factors computed from literals (`1 * 1`, `-1.0`, `0.5 * 2`),
then scalings by them, and negations that autodiff writes around products
(`wa·wb·(−sin δ)` in one place, `wa·wb·(−(−1·sin δ))` in another — one product
twice). Here, as `graph` lowers each operation:

- an operation whose inputs are all constants is evaluated once, at lowering,
  and becomes a constant (so `Builder.constant_is` sees the 1s and −1s it makes);
- x·(−1) is −x; −(−x) is x;
- a product or quotient of negated factors is the negation of the product of the
  factors, so equal products meet in the common-subexpression table;
- a sum or difference absorbs its operands' negations: a + (−b) = a − b,
  (−a) + b = b − a, a − (−b) = a + b, (−a) − (−b) = b − a, (−a) ± (−b) = −(a ± b).

Every rewrite is exact in floating point (negation is exact, and IEEE addition
and multiplication are symmetric in sign); a product's factors are put in a fixed
order, which reverses the summation order of some Cauchy sums, so coefficients
agree with the unfolded graph's to rounding, not bit for bit. The double
pendulum's graph: 9 → 8 products and 38 → 28 series operations (`Graph.census`).

References: the same rules as `lagjax.taylor.heyoka_signs` for the heyoka
translation; Muller et al., *Handbook of Floating-Point Arithmetic* (2018), §2
(exactness of negation).
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import numpy as np
from jax.core import Tracer

import lagjax.taylor.recurrences as rec

# Constant operations folded at lowering only up to this many elements: a large
# constant array computed at trace time would be baked into the program.
FOLD_SIZE = 64


@functools.cache
def default_params(name: str) -> dict:
    """The params a jaxpr gives the elementwise primitive `name` (jax 0.10's
    `mul` carries `out_dtype=None`, which its transpose rule requires): a rule
    made here must look like one read off a jaxpr, for `jax.grad` to enter it."""
    operands = (1.0,) if name == "neg" else (1.0, 1.0)
    jaxpr = jax.make_jaxpr(getattr(jax.lax, name))(*operands)
    return dict(jaxpr.eqns[0].params)


def foldable(eqn: Any, ins: list[int], constants: dict) -> bool:
    """Whether `eqn` has only constant inputs and small, effect-free outputs."""
    return (
        all(i in constants for i in ins)
        # A closed-over value of an outer trace (a vmapped parameter) is a
        # constant of this jaxpr but has no value yet.
        and not any(isinstance(constants[i], Tracer) for i in ins)
        and not eqn.effects
        and all(
            np.prod(v.aval.shape, dtype=int) <= FOLD_SIZE and hasattr(v.aval, "dtype")
            for v in eqn.outvars
        )
    )


def fold(eqn: Any, values: list[Any]) -> list[Any]:
    """`eqn` evaluated on concrete `values`, now (not staged into a trace): the
    results are concrete arrays (a NumPy array given to `jnp.asarray` inside a
    trace would come back a tracer)."""
    with jax.ensure_compile_time_eval():
        out = eqn.primitive.bind(*values, **eqn.params)
    return list(out) if eqn.primitive.multiple_results else [out]


class Signs:
    """Which series values are the negation of which (value id → value id), and
    how to emit sign-aware operations through a graph builder."""

    def __init__(self, builder: Any) -> None:
        self.builder = builder
        self.negation_of: dict[int, int] = {}

    def split(self, x: int) -> tuple[int, int]:
        """(sign, base) with x = sign · base."""
        base = self.negation_of.get(x)
        return (1, x) if base is None else (-1, base)

    def negate(self, x: int) -> int:
        """−x: the base of a negation, or one more negation (shared)."""
        if x in self.negation_of:
            return self.negation_of[x]
        rule = rec.Affine(
            primitive=jax.lax.neg_p, params=default_params("neg"), series=(True,)
        )
        aval = self.builder.avals[x]
        (out,) = self.builder.emit(rule, [x], [aval], True, key=("neg", (x,), ()))
        self.negation_of[out] = x
        return out

    def signed(self, sign: int, x: int) -> int:
        return x if sign > 0 else self.negate(x)

    def product(self, name: str, a: int, b: int, aval: Any) -> int:
        """a·b or a/b of two series values, negations taken outside."""
        (sa, a), (sb, b) = self.split(a), self.split(b)
        if name == "mul":
            a, b = sorted((a, b))  # a·b and b·a meet in the table
        return self.signed(sa * sb, self.builder.primitive(name, (a, b), aval))

    def quotient_of_fixed(self, a: int, b: int, aval: Any) -> int:
        """a/b with a fixed and b a series value: −(a/b') for b = −b'."""
        sb, b = self.split(b)
        return self.signed(sb, self.builder.primitive("div", (a, b), aval))

    def linear(self, name: str, a: int, b: int, aval: Any) -> int:
        """a + b or a − b of two series values, their negations absorbed."""
        (sa, a), (sb, b) = self.split(a), self.split(b)
        if name == "sub":
            sb = -sb
        if sa > 0 and sb > 0:
            return self._emit("add", a, b, aval)
        if sa > 0:
            return self._emit("sub", a, b, aval)  # a − b
        if sb > 0:
            return self._emit("sub", b, a, aval)  # b − a
        return self.negate(self._emit("add", a, b, aval))  # −(a + b)

    def _emit(self, name: str, a: int, b: int, aval: Any) -> int:
        prim = getattr(jax.lax, f"{name}_p")
        rule = rec.Affine(
            primitive=prim, params=default_params(name), series=(True, True)
        )
        ins = sorted((a, b)) if name == "add" else [a, b]
        key = (name, tuple(ins), ())
        return self.builder.emit(rule, ins, [aval], True, key=key)[0]


def rewrite(
    signs: Signs, name: str, ins: list[int], flags: tuple[bool, ...], avals: list
) -> tuple[int, ...] | None:
    """The sign-aware lowering of an elementwise neg, mul, div, add or sub with a
    series input, or None to lower it as it stands (broadcasting operations, and
    a fixed operand in a sum)."""
    builder, aval = signs.builder, avals[0]
    if name not in ("neg", "mul", "div", "add", "sub") or len(avals) != 1:
        return None
    if any(builder.avals[i].shape != aval.shape for i in ins):
        return None
    if name == "neg":
        return (signs.negate(ins[0]),)
    if all(flags):
        if name in ("mul", "div"):
            return (signs.product(name, ins[0], ins[1], aval),)
        return (signs.linear(name, ins[0], ins[1], aval),)
    if name == "mul":  # one fixed factor
        fixed, series = (ins[0], ins[1]) if flags[1] else (ins[1], ins[0])
        if builder.constant_is(fixed, -1.0):
            return (signs.negate(series),)
        sign, base = signs.split(series)
        scaled = [fixed, base] if flags[1] else [base, fixed]
        rule = rec.Scale(
            primitive=jax.lax.mul_p, params=default_params("mul"), series=flags
        )
        key = ("mul", tuple(scaled), ())
        return (signs.signed(sign, builder.emit(rule, scaled, [aval], True, key)[0]),)
    if name == "div" and flags == (False, True):
        return (signs.quotient_of_fixed(ins[0], ins[1], aval),)
    return None
