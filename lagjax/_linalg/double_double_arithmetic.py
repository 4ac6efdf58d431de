r"""Double-double arithmetic: a number as the unevaluated sum hi + lo of two float64s.

A double-double $x = x_{hi} + x_{lo}$ with $|x_{lo}| \le \tfrac12\,\mathrm{ulp}(x_{hi})$
carries about 106 bits (relative precision ≈ 1.2e-32 against float64's 1.1e-16),
from float64 operations alone, so it runs wherever XLA runs, vectorized and under
`jit`, `vmap` and `grad`. The building blocks are error-free transformations:
`two_sum` returns s = fl(a + b) and the exact rounding error e, a + b = s + e
(Knuth); `two_product` does the same for a·b by Dekker's splitting of each factor
into 26-bit halves (no fused multiply-add needed). Every operation below is
built from them, with the error bounds of the QD library's "accurate" variants
(Hida, Li & Bailey): relative error a few units of 2⁻¹⁰⁶.

They rely on IEEE float64 rounding evaluated as written. XLA's CPU compiler does
not reassociate (no fast-math by default), but LLVM contracts a product that
feeds a sum inside one fused kernel into a fused multiply-add, and XLA's fusion
recomputes a cheap product in each consumer. Then fl(a·b) in one place and the
exact a·b + c in another meet in one formula, and the error term counts the
product's rounding twice (x·x for x = 0.58 + 1.3e-18 came out half an ulp
wrong). `lax.optimization_barrier` does not prevent it (XLA's CPU pipeline
removes the barrier before fusion), nor do a no-op `reduce_precision` or a
bitcast round trip (simplified away). What does: every product whose rounding a
formula relies on (Dekker's t = (2²⁷+1)·a and p = fl(a·b)) and every operand
of an error-free sum goes through `_stored`, a select on x = x that keeps x
(NaN too), which LLVM cannot contract through. The tests check every
operation against exact rational arithmetic under `jit`.

References:
    T. J. Dekker, "A floating-point technique for extending the available
    precision", Numer. Math. 18, 224 (1971); D. E. Knuth, *The Art of Computer
    Programming* vol. 2, §4.2.2; Y. Hida, X. S. Li & D. H. Bailey, "Algorithms
    for quad-double precision floating point arithmetic", ARITH-15 (2001).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

# 2²⁷ + 1: Dekker's splitter for float64's 53-bit significand.
SPLITTER = 134217729.0


class DoubleDouble(NamedTuple):
    """hi + lo, two float64 arrays of one shape (a pytree: maps and vmaps as one)."""

    hi: jax.Array
    lo: jax.Array


def from_double(x: Any) -> DoubleDouble:
    x = jnp.asarray(x)
    return DoubleDouble(x, jnp.zeros_like(x))


def two_sum(a: jax.Array, b: jax.Array) -> DoubleDouble:
    """s + e = a + b exactly, s = fl(a + b) (Knuth: no condition on |a|, |b|)."""
    s = a + b
    b_virtual = s - a
    a_virtual = s - b_virtual
    return DoubleDouble(s, (a - a_virtual) + (b - b_virtual))


def fast_two_sum(a: jax.Array, b: jax.Array) -> DoubleDouble:
    """s + e = a + b exactly when |a| ≥ |b| (or a = 0) (Dekker)."""
    s = a + b
    return DoubleDouble(s, b - (s - a))


def _stored(x: Any) -> Any:
    """x as a value no consumer can fuse into a multiply-add (module docstring):
    where(x = x, x, x + x) is x, NaN included."""
    return jax.tree_util.tree_map(lambda v: jnp.where(v == v, v, v + v), x)


def _split(a: jax.Array) -> tuple[jax.Array, jax.Array]:
    """a = high + low, each with at most 26 significant bits."""
    t = _stored(SPLITTER * a)
    high = t - (t - a)
    return high, a - high


def two_product(a: jax.Array, b: jax.Array) -> DoubleDouble:
    """p + e = a·b exactly, p = fl(a·b) (Dekker; |a·b| well below overflow)."""
    p = _stored(a * b)
    a_high, a_low = _split(a)
    b_high, b_low = _split(b)
    error = ((a_high * b_high - p) + a_high * b_low + a_low * b_high) + a_low * b_low
    return DoubleDouble(p, error)


def add(x: DoubleDouble, y: DoubleDouble) -> DoubleDouble:
    """x + y with an error of a few 2⁻¹⁰⁶ (|x| + |y|): relative to the operands,
    not to a result that cancels them (the QD library's "sloppy" sum; half the
    work of the accurate one, and what a step of an ODE needs)."""
    s, e = two_sum(x.hi, y.hi)
    return fast_two_sum(s, e + (x.lo + y.lo))


def add_double(x: DoubleDouble, b: jax.Array) -> DoubleDouble:
    """x + b for a float64 b."""
    s, e = two_sum(x.hi, b)
    return fast_two_sum(s, e + x.lo)


def negate(x: DoubleDouble) -> DoubleDouble:
    return DoubleDouble(-x.hi, -x.lo)


def subtract(x: DoubleDouble, y: DoubleDouble) -> DoubleDouble:
    return add(x, negate(y))


def multiply(x: DoubleDouble, y: DoubleDouble) -> DoubleDouble:
    """x·y, relative error ≤ 4·2⁻¹⁰⁶ (the lo·lo term is below it)."""
    p, e = two_product(x.hi, y.hi)
    return fast_two_sum(p, e + (x.hi * y.lo + x.lo * y.hi))


def multiply_double(x: DoubleDouble, b: jax.Array) -> DoubleDouble:
    """x·b for a float64 b."""
    p, e = two_product(x.hi, b)
    return fast_two_sum(p, e + x.lo * b)


def divide(x: DoubleDouble, y: DoubleDouble) -> DoubleDouble:
    """x / y by long division: two quotient digits, the second from the
    remainder x − q₁y (relative error a few 2⁻¹⁰⁶)."""
    q1 = x.hi / y.hi
    remainder = subtract(x, multiply_double(y, q1))
    return fast_two_sum(q1, remainder.hi / y.hi)


def divide_double(x: DoubleDouble, b: jax.Array) -> DoubleDouble:
    """x / b for a float64 b: x.hi − q₁b is exact (it cancels), so one product."""
    q1 = x.hi / b
    p, e = two_product(q1, b)
    return fast_two_sum(q1, (((x.hi - p) - e) + x.lo) / b)


def square_root(x: DoubleDouble) -> DoubleDouble:
    """√x by one Newton correction of the float64 root (Karp & Markstein): s + (x −
    s²)/(2s); 0 at 0, NaN below."""
    s = jnp.sqrt(x.hi)
    safe = jnp.where(s > 0, s, 1.0)
    remainder = subtract(x, two_product(safe, safe))
    correction = jnp.where(s > 0, remainder.hi / (2 * safe), 0.0)
    return fast_two_sum(s, correction)


def integer_power(x: DoubleDouble, n: int) -> DoubleDouble:
    """xⁿ by repeated squaring; a negative n is the reciprocal of x^|n|."""
    result, base, k = from_double(jnp.ones_like(x.hi)), x, abs(n)
    while k:
        if k & 1:
            result = multiply(result, base)
        k >>= 1
        if k:
            base = multiply(base, base)
    return divide(from_double(jnp.ones_like(x.hi)), result) if n < 0 else result


def sign_of_difference(x: DoubleDouble, y: DoubleDouble) -> jax.Array:
    """The sign of x − y (−1, 0 or 1), exact: comparisons of double-doubles."""
    difference = subtract(x, y)
    return jnp.sign(jnp.where(difference.hi != 0, difference.hi, difference.lo))


def to_double(x: DoubleDouble) -> jax.Array:
    """The float64 nearest x (hi, once normalised: |lo| ≤ ulp(hi)/2)."""
    return x.hi + x.lo
