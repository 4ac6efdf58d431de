"""Taylor-coefficient recurrences, one rule per kind of elementary operation.

Along a solution y(t) of y' = f(t, y), every intermediate value v of the vector
field is a function of time with a Taylor series v(t₀ + τ) = Σₖ vₖ τᵏ. Given the
coefficients 0..k of a rule's inputs (and 0..k-1 of its outputs), its rule gives
the k-th coefficient of its outputs. With the Cauchy product

    (a ⋆ b)ₖ = Σ_{j=0}^{k} aⱼ bₖ₋ⱼ

the rules are, for k ≥ 1 (writing (j a)ⱼ = j aⱼ):

| operation                 | k-th coefficient                                      |
|---------------------------|-------------------------------------------------------|
| affine (add, slice, …)    | the operation applied to the inputs' k-th coefficients |
| c = a · b                 | (a ⋆ b)ₖ                                              |
| c = a / b                 | (aₖ − (b ⋆ c)ₖ) / b₀                                  |
| c = exp a                 | ((j a) ⋆ c)ₖ / k                                      |
| c = log a                 | (aₖ − ((j c) ⋆ a)ₖ / k) / a₀                          |
| c = a^α (α fixed)         | (α (c ⋆ a)ₖ − (α + 1) ((j c) ⋆ a)ₖ / k) / a₀          |
| c = √a                    | (aₖ − (c ⋆ c)ₖ) / (2 c₀)                              |
| s, c = sin a, cos a       | sₖ = ((j a) ⋆ c)ₖ / k,  cₖ = −((j a) ⋆ s)ₖ / k        |
| t, u = tan a, 1 + t²      | tₖ = ((j a) ⋆ u)ₖ / k,  uₖ = (t ⋆ t)ₖ                 |
| abs, max, min             | the branch chosen by the order-0 values               |

where the output's own k-th coefficient, still zero when the sum is formed,
drops out of the products it appears in. Each rule costs one transcendental
function at order 0 and multiply-adds above.

A series is either a Python list of P coefficient arrays with a Python int k
(an unrolled sweep over the orders: straight-line arithmetic XLA fuses), or an
array of shape (P, *shape) over the order axis with a traced k (a `fori_loop`
over the orders: a dynamic window); in both the entries above the current order
are zero. Fixed values (parameters, comparisons of order-0 values) are
plain arrays and contribute to order 0 only.

References:
    Moore, "Interval Analysis" (1966), ch. 11; Hairer, Nørsett & Wanner, "Solving
    Ordinary Differential Equations I" (1993), §I.8; Jorba & Zou, "A software
    package for the numerical integration of ODEs by means of high-order Taylor
    methods", Experimental Mathematics 14 (2005); Biscani & Izzo, "Revisiting
    high-order Taylor methods for astrodynamics and celestial mechanics", MNRAS
    504 (2021).
"""

from __future__ import annotations

import abc
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from .vector_sincos import sin_cos


def _window(b: jax.Array, k: Any) -> jax.Array:
    """wⱼ = bₖ₋ⱼ for j = 0..P-1 (zero for j > k), for a traced k."""
    size = b.shape[0]
    reversed_padded = jnp.concatenate([b[::-1], jnp.zeros_like(b)])
    return jax.lax.dynamic_slice_in_dim(reversed_padded, size - 1 - k, size)


def cauchy(a: Any, b: Any, k: Any) -> jax.Array:
    """(a ⋆ b)ₖ = Σ_{j=0}^{k} aⱼ bₖ₋ⱼ."""
    if isinstance(a, list):
        total = a[0] * b[k]
        for j in range(1, k + 1):
            total = total + a[j] * b[k - j]
        return total
    # A scalar operand of an array one (lax broadcasts rank 0): its orders
    # broadcast along the other's element axes, not against the order axis.
    rank = max(a.ndim, b.ndim)
    a, b = (x.reshape(x.shape + (1,) * (rank - x.ndim)) for x in (a, b))
    return jnp.sum(a * _window(b, k), axis=0)


def weighted(a: Any) -> Any:
    """(j aⱼ)ⱼ: the coefficients of τ a'(τ)."""
    if isinstance(a, list):
        return [jnp.zeros_like(a[0])] + [j * x for j, x in enumerate(a[1:], 1)]
    j = jnp.arange(a.shape[0], dtype=a.dtype).reshape((-1,) + (1,) * (a.ndim - 1))
    return j * a


def with_coefficient(x: Any, k: Any, value: jax.Array) -> Any:
    """x with its k-th coefficient set to `value`."""
    if isinstance(x, list):
        return [value if j == k else c for j, c in enumerate(x)]
    # A dynamic update in place (`.at[k].set` would be a scatter).
    return jax.lax.dynamic_update_index_in_dim(x, value.astype(x.dtype), k, 0)


def coefficient(x: jax.Array, k: Any, series: bool) -> jax.Array:
    """The k-th (k ≥ 1) coefficient of an input: a fixed float value is constant
    in time, so it contributes nothing above order 0."""
    if series:
        return x[k]
    return jnp.zeros_like(x) if jnp.issubdtype(x.dtype, jnp.inexact) else x


class AbstractRule(eqx.Module):
    """How one operation's outputs get their Taylor coefficients.

    `series[i]` says whether input i varies along the solution (a series, shape
    (P, *shape)) or is fixed within the step (a plain value).
    """

    series: eqx.AbstractVar[tuple[bool, ...]]

    @abc.abstractmethod
    def zero(self, *inputs: Any) -> tuple[Any, ...]:
        """The order-0 outputs from the order-0 inputs (plain evaluation)."""

    @abc.abstractmethod
    def coefficient(self, k: Any, inputs: tuple, outputs: tuple) -> tuple[Any, ...]:
        """The k-th coefficient of each output, k ≥ 1."""


class AbstractPrimitiveRule(AbstractRule):
    """A rule whose order-0 value is the primitive itself."""

    primitive: eqx.AbstractVar[Any]
    params: eqx.AbstractVar[dict]

    def zero(self, *inputs):
        out = self.primitive.bind(*inputs, **self.params)
        return tuple(out) if self.primitive.multiple_results else (out,)

    def _bind(self, *inputs):
        out = self.primitive.bind(*inputs, **self.params)
        return tuple(out) if self.primitive.multiple_results else (out,)


class Fixed(AbstractPrimitiveRule):
    """Constant within a step (comparisons, integer arithmetic, parameters, and
    piecewise-constant functions such as `sign` of a series): order 0 only."""

    primitive: Any = eqx.field(static=True)
    params: dict = eqx.field(static=True)
    series: tuple[bool, ...] = eqx.field(static=True)

    def coefficient(self, k, inputs, outputs):
        return tuple(jnp.zeros_like(y[0]) for y in outputs)


class Affine(AbstractPrimitiveRule):
    """Jointly linear in its float inputs (add, sub, neg, slice, concatenate,
    select_n, reshape, …): the operation of the inputs' k-th coefficients."""

    primitive: Any = eqx.field(static=True)
    params: dict = eqx.field(static=True)
    series: tuple[bool, ...] = eqx.field(static=True)

    def coefficient(self, k, inputs, outputs):
        return self._bind(*map(coefficient, inputs, [k] * len(inputs), self.series))


class Scale(AbstractPrimitiveRule):
    """A bilinear operation (mul, dot_general) or a division with one fixed
    operand: linear in the series, the fixed operand kept as it is."""

    primitive: Any = eqx.field(static=True)
    params: dict = eqx.field(static=True)
    series: tuple[bool, ...] = eqx.field(static=True)

    def coefficient(self, k, inputs, outputs):
        args = [x[k] if s else x for x, s in zip(inputs, self.series)]
        return self._bind(*args)


class Product(AbstractPrimitiveRule):
    """a · b or dot_general(a, b) of two series: the Cauchy product."""

    primitive: Any = eqx.field(static=True)
    params: dict = eqx.field(static=True)
    series: tuple[bool, ...] = eqx.field(static=True)

    def coefficient(self, k, inputs, outputs):
        a, b = inputs
        if self.primitive.name == "mul":
            return (cauchy(a, b, k),)
        # A bilinear map of arrays: the same sum with the map in place of `*`.
        bind = lambda u, v: self.primitive.bind(u, v, **self.params)
        if isinstance(a, list):
            return (sum(bind(a[j], b[k - j]) for j in range(k + 1)),)
        return (jnp.sum(jax.vmap(bind)(a, _window(b, k)), axis=0),)


class Quotient(AbstractPrimitiveRule):
    """c = a / b with b a series (a a series or fixed)."""

    primitive: Any = eqx.field(static=True)
    params: dict = eqx.field(static=True)
    series: tuple[bool, ...] = eqx.field(static=True)

    def coefficient(self, k, inputs, outputs):
        (a, b), (c,) = inputs, outputs
        return ((coefficient(a, k, self.series[0]) - cauchy(b, c, k)) / b[0],)


class Exp(AbstractPrimitiveRule):
    """c = exp a (and expm1: the same series less 1 at order 0)."""

    primitive: Any = eqx.field(static=True)
    params: dict = eqx.field(static=True)
    series: tuple[bool, ...] = eqx.field(static=True)

    def coefficient(self, k, inputs, outputs):
        (a,), (c,) = inputs, outputs
        if self.primitive.name == "expm1":
            # exp a = c + 1: the extra 1 at order 0 adds k a_k to the sum.
            return (cauchy(weighted(a), c, k) / k + a[k],)
        return (cauchy(weighted(a), c, k) / k,)


class Log(AbstractPrimitiveRule):
    """c = log a (and log1p: the same with a₀ replaced by 1 + a₀)."""

    primitive: Any = eqx.field(static=True)
    params: dict = eqx.field(static=True)
    series: tuple[bool, ...] = eqx.field(static=True)

    def coefficient(self, k, inputs, outputs):
        (a,), (c,) = inputs, outputs
        a0 = a[0] + 1 if self.primitive.name == "log1p" else a[0]
        return ((a[k] - cauchy(weighted(c), a, k) / k) / a0,)


class Power(AbstractRule):
    """c = a^α for a fixed real α, the second input (pow by a fixed exponent,
    rsqrt, cbrt). Divides by a₀: a series through a = 0 needs an integer power,
    which the lowering turns into products instead."""

    series: tuple[bool, ...] = eqx.field(static=True)

    def zero(self, a, alpha):
        return (a**alpha,)

    def coefficient(self, k, inputs, outputs):
        (a, alpha), (c,) = inputs, outputs
        jc = weighted(c)
        return ((alpha * cauchy(c, a, k) - (alpha + 1) * cauchy(jc, a, k) / k) / a[0],)


class Sqrt(AbstractRule):
    """c = √a: c ⋆ c = a, solved for the new coefficient."""

    series: tuple[bool, ...] = eqx.field(static=True)

    def zero(self, a):
        return (jnp.sqrt(a),)

    def coefficient(self, k, inputs, outputs):
        (a,), (c,) = inputs, outputs
        return ((a[k] - cauchy(c, c, k)) / (2 * c[0]),)


class SinCos(AbstractRule):
    """(sin a, cos a), each the other's derivative factor."""

    series: tuple[bool, ...] = eqx.field(static=True)

    def zero(self, a):
        # Not jnp.sin/jnp.cos: on a CPU those are a libm call per element.
        return sin_cos(a)

    def coefficient(self, k, inputs, outputs):
        (a,), (s, c) = inputs, outputs
        ja = weighted(a)
        return (cauchy(ja, c, k) / k, -cauchy(ja, s, k) / k)


class TanLike(AbstractRule):
    """(t, u) = (tan a, 1 + t²) or (tanh a, 1 − t²): t' = u a'."""

    hyperbolic: bool = eqx.field(static=True)
    series: tuple[bool, ...] = eqx.field(static=True)

    def zero(self, a):
        if self.hyperbolic:
            t = jnp.tanh(a)
            return (t, 1 - t * t)
        t = jnp.tan(a)
        return (t, 1 + t * t)

    def coefficient(self, k, inputs, outputs):
        (a,), (t, u) = inputs, outputs
        tk = cauchy(weighted(a), u, k) / k
        t = with_coefficient(t, k, tk)
        square = cauchy(t, t, k)
        return (tk, -square if self.hyperbolic else square)


class Branch(AbstractPrimitiveRule):
    """abs, max, min: the branch the order-0 values select, kept for the step
    (a step that crosses the kink is as accurate as the step-size rule can see)."""

    primitive: Any = eqx.field(static=True)
    params: dict = eqx.field(static=True)
    series: tuple[bool, ...] = eqx.field(static=True)

    def coefficient(self, k, inputs, outputs):
        coeffs = [coefficient(x, k, s) for x, s in zip(inputs, self.series)]
        orders0 = [x[0] if s else x for x, s in zip(inputs, self.series)]
        name = self.primitive.name
        if name == "abs":
            return (jnp.where(orders0[0] >= 0, coeffs[0], -coeffs[0]),)
        first = orders0[0] >= orders0[1] if name == "max" else orders0[0] <= orders0[1]
        return (jnp.where(first, coeffs[0], coeffs[1]),)


class LinearSolve(AbstractPrimitiveRule):
    """x = M⁻¹ b, a marked solve call (`lagjax._linalg.marked_solves`) whose
    outputs are (x, singular); this rule gives x. From M x = b,

        xₖ = M₀⁻¹ (bₖ − Σ_{j=1}^{k} Mⱼ xₖ₋ⱼ)

    (the j = 0 term drops out: xₖ is still zero when the sum is formed)."""

    primitive: Any = eqx.field(static=True)
    params: dict = eqx.field(static=True)
    series: tuple[bool, ...] = eqx.field(static=True)

    def zero(self, *inputs):
        return self._bind(*inputs)[:1]

    def coefficient(self, k, inputs, outputs):
        (m, b), (x,) = inputs, outputs
        residual = coefficient(b, k, self.series[1])
        if not self.series[0]:
            return (jnp.linalg.solve(m, residual),)
        if isinstance(m, list):
            coupling = sum(m[j] @ x[k - j] for j in range(1, k + 1))
        else:
            coupling = jnp.sum(jax.vmap(jnp.matmul)(m, _window(x, k)), axis=0)
        return (jnp.linalg.solve(m[0], residual - coupling),)
