r"""Hermite continuous extensions: states between the steps of a fixed-step solver.

lagjax's fixed-step methods (splittings, Gauss–Legendre, RATTLE, Lie–Poisson,
variational) return only the state at the step ends, so diffrax's default for them
is linear interpolation, exact to $O(h^2)$ only. Between $t_0$ and $t_1 = t_0 + h$,
with $s = (t - t_0)/h$, a Hermite polynomial through the end states and their
derivatives does better at little cost:

- **cubic** through $y_0, y_1$ and $k_i = h\,f(t_i, y_i)$: interpolation error
  $h^4 \max|y^{(4)}|/384$, so the state between the steps is $O(h^{\min(p, 4)})$
  for a method of order $p$ — the method's own order for $p \le 4$;
- **quintic** through also $m_i = h^2 \ddot y_i$, $\ddot y = \partial_t f + f'(y) f$
  (one Jacobian–vector product at each end): error $O(h^6)$, so order
  $\min(p, 6)$.

| solver | order p | extension | order between steps |
|---|---|---|---|
| StormerVerlet, ImplicitMidpoint, Rattle, VariationalMidpoint, RigidBodyVerlet | 2 | cubic | 2 |
| Yoshida4, BlanesMoan4, GaussLegendre(2), RigidBodyYoshida4 | 4 | cubic | 4 |
| Yoshida6, GaussLegendre(3) | 6 | quintic | 6 |
| KahanLi8, SofSpa10 | 8, 10 | quintic | 6 |

`HermiteDenseOutput` wraps any solver and returns the dense information its
interpolation needs. The wrap is applied by `simulate` only when a run needs states
between steps (`ts` off the step grid, `dense=True`, an event): the vector fields it
evaluates cost nothing in runs that do not ask for them.

??? cite "References"

    - Hairer, Nørsett & Wanner, *Solving Ordinary Differential Equations I*, 2nd ed.,
      Springer (1993), §II.6 (dense output, Hermite interpolation).
    - Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
      Springer (2006), §VIII.6 (dense output of symplectic methods).
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._core.terms import time_direction

# The quintic Hermite polynomial p(s) = Σ c_j s^j through y0, y1, k0, k1, m0, m1
# (k = h y', m = h² y''): rows are the powers s⁵ … s⁰ (numpy.polyval order), columns
# the weights of (y0, y1, k0, k1, m0, m1).
_QUINTIC = (
    (-6.0, 6.0, -3.0, -3.0, -0.5, 0.5),
    (15.0, -15.0, 8.0, 7.0, 1.5, -1.0),
    (-10.0, 10.0, -6.0, -4.0, -1.5, 0.5),
    (0.0, 0.0, 0.0, 0.0, 0.5, 0.0),
    (0.0, 0.0, 1.0, 0.0, 0.0, 0.0),
    (1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
)


class QuinticHermiteInterpolation(diffrax.AbstractLocalInterpolation):
    r"""The quintic through $y_0, y_1$, $k_i = h\dot y_i$ and $m_i = h^2\ddot y_i$.

    Interpolation error $O(h^6)$ on $[t_0, t_1]$ (Hairer, Nørsett & Wanner §II.6).
    """

    t0: Any
    t1: Any
    coeffs: Any

    def __init__(self, *, t0, t1, y0, y1, k0, k1, m0, m1):
        def combine(*values):
            with jax.numpy_dtype_promotion("standard"):
                rows = [
                    sum(weight * value for weight, value in zip(row, values))
                    for row in _QUINTIC
                ]
            return jnp.stack([jnp.asarray(r, jnp.result_type(values[0])) for r in rows])

        self.t0 = t0
        self.t1 = t1
        self.coeffs = jax.tree_util.tree_map(combine, y0, y1, k0, k1, m0, m1)

    def evaluate(self, t0, t1=None, left=True):
        del left
        if t1 is not None:
            return jax.tree_util.tree_map(
                jnp.subtract, self.evaluate(t1), self.evaluate(t0)
            )
        s = _fraction_of_step(self.t0, t0, self.t1)

        def polynomial(coeffs):
            with jax.numpy_dtype_promotion("standard"):
                return jnp.polyval(coeffs, s).astype(coeffs.dtype)

        return jax.tree_util.tree_map(polynomial, self.coeffs)


def _scaled(tree: Any, factor: Any) -> Any:
    return jax.tree_util.tree_map(lambda x: (x * factor).astype(x.dtype), tree)


class HermiteDenseOutput(diffrax.AbstractWrappedSolver):
    """`solver` with a Hermite continuous extension (module docstring).

    `quintic` adds the second derivatives at the step ends (order 6 between steps
    instead of 4); `for_solver` picks it for methods of order above 4. Every other
    property — adaptivity, implicitness, the order — is the wrapped solver's.
    """

    solver: diffrax.AbstractSolver
    quintic: bool = eqx.field(static=True, default=False)

    @classmethod
    def for_solver(cls, solver: diffrax.AbstractSolver, terms: Any):
        order = solver.order(terms) or 1
        return cls(solver, quintic=order > 4)

    @property
    def term_structure(self):  # pyright: ignore[reportIncompatibleVariableOverride]
        return self.solver.term_structure

    @property
    def interpolation_cls(self):  # pyright: ignore[reportIncompatibleVariableOverride]
        if self.quintic:
            return QuinticHermiteInterpolation
        return diffrax.ThirdOrderHermitePolynomialInterpolation

    @property
    def root_finder(self):
        """The wrapped implicit solver's (diffrax reads it after `isinstance`)."""
        return self.solver.root_finder  # pyright: ignore[reportAttributeAccessIssue]

    def order(self, terms: Any) -> int | None:
        return self.solver.order(terms)

    def error_order(self, terms: Any):
        return self.solver.error_order(terms)

    def init(self, terms, t0, t1, y0, args):
        """The wrapped solver's state, and the derivatives at the start (carried
        from each step's end to the next step's start: first-same-as-last)."""
        inner = self.solver.init(terms, t0, t1, y0, args)
        return inner, self._derivatives(terms, t0, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        inner, start = solver_state
        if made_jump is not False:
            # After a jump the carried derivatives belong to the old vector field.
            start = jax.lax.cond(
                made_jump, lambda: self._derivatives(terms, t0, y0, args), lambda: start
            )
        y1, error, _, inner, result = self.solver.step(
            terms, t0, t1, y0, args, inner, made_jump
        )
        end = self._derivatives(terms, t1, y1, args)
        h = t1 - t0
        dense_info = dict(y0=y0, y1=y1, k0=_scaled(start[0], h), k1=_scaled(end[0], h))
        if self.quintic:
            dense_info.update(m0=_scaled(start[1], h * h), m1=_scaled(end[1], h * h))
        return y1, error, dense_info, (inner, end), result

    def _derivatives(self, terms, t, y, args) -> tuple[Any, Any]:
        """(ẏ, ÿ) at (t, y); ÿ = ∂f/∂t + f'(y)·f by one Jacobian–vector product
        (empty for the cubic)."""

        # A backward run (t1 < t0) reaches the solver in reversed time τ = −t, with
        # diffrax's direction in the terms' `contr` and not in `vf`: the slopes the
        # Hermite polynomial needs are dy/dτ = direction · f.
        direction = time_direction(terms)

        def field(time, state):
            rate = self.solver.func(terms, time, state, args)
            return jax.tree_util.tree_map(
                lambda x: (direction * x).astype(jnp.result_type(x)), rate
            )

        if not self.quintic:
            return field(t, y), ()
        rate = field(t, y)
        one = jnp.ones_like(jnp.asarray(t))
        _, acceleration = jax.jvp(field, (t, y), (one, rate))
        return rate, acceleration

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)

    def dense_information(self, terms, times, ys, args) -> dict[str, Any]:
        """The dense information of every step of a run from its states `ys` at
        `times` (stacked, one more than the steps), as `step` gives it step by
        step: for a run whose states were kept without it (the reversible
        adjoint)."""
        derivatives = jax.vmap(lambda t, y: self._derivatives(terms, t, y, args))(
            times, ys
        )
        h = times[1:] - times[:-1]

        def scaled(tree, power, part):
            return jax.tree_util.tree_map(
                lambda x: (x[part] * _column(h, x[part]) ** power).astype(x.dtype),
                tree,
            )

        first, last = slice(None, -1), slice(1, None)
        pick = lambda tree, part: jax.tree_util.tree_map(lambda x: x[part], tree)
        info = dict(
            y0=pick(ys, first),
            y1=pick(ys, last),
            k0=scaled(derivatives[0], 1, first),
            k1=scaled(derivatives[0], 1, last),
        )
        if self.quintic:
            info.update(
                m0=scaled(derivatives[1], 2, first), m1=scaled(derivatives[1], 2, last)
            )
        return info

    def state_at(self, terms, t, y, args, inner):
        """This solver's state at (t, y) from the wrapped solver's state `inner`:
        a step taken from there gives the same dense information as one inside a
        run of this solver (the start derivatives computed afresh, not carried)."""
        return inner, self._derivatives(terms, t, y, args)

    @staticmethod
    def inner_state(state):
        """The wrapped solver's state within this solver's."""
        return state[0]


def _column(h: jax.Array, like: jax.Array) -> jax.Array:
    return h.reshape(h.shape + (1,) * (like.ndim - 1))


def _fraction_of_step(start: Any, t: Any, end: Any) -> Any:
    """(t − start)/(end − start), and 0 on a zero-length step (no division by 0, so
    no NaN reaches the gradient either)."""
    span = end - start
    zero = span == 0
    return jnp.where(zero, 0.0, (t - start) / jnp.where(zero, 1.0, span))


def needs_hermite(solver: diffrax.AbstractSolver) -> bool:
    """Whether `solver`'s own interpolation is only linear between steps."""
    return solver.interpolation_cls is diffrax.LocalLinearInterpolation


def with_dense_output(
    solver: diffrax.AbstractSolver, terms: Any
) -> diffrax.AbstractSolver:
    """`solver` with the Hermite extension if its own is linear, else itself."""
    if needs_hermite(solver):
        return HermiteDenseOutput.for_solver(solver, terms)
    return solver
