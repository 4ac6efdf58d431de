"""`AbstractProjectedSolver`: any diffrax solver, with a projection after every step.

Projection methods (Hairer, Lubich & Wanner, *Geometric Numerical Integration*,
§IV.4) keep a state on a manifold — unit quaternions, a constraint surface — by
taking an ordinary step and mapping the result back. The wrapper delegates
everything to the wrapped solver (so `isinstance` checks for adaptivity are the
wrapped solver's) and only replaces `y1`, in the state and the dense output, by its
projection; a subclass says what the projection is.
"""

from __future__ import annotations

import abc
from typing import Any

import diffrax
import equinox as eqx

from lagjax.precision import match_dtypes


class AbstractProjectedSolver(diffrax.AbstractWrappedSolver):
    """Delegates to `solver` and projects each step's end state with `project`."""

    solver: eqx.AbstractVar[diffrax.AbstractSolver]

    @property
    def term_structure(self):  # pyright: ignore[reportIncompatibleVariableOverride]
        return self.solver.term_structure

    @property
    def interpolation_cls(self):  # pyright: ignore[reportIncompatibleVariableOverride]
        return self.solver.interpolation_cls

    def order(self, terms: Any) -> int | None:
        return self.solver.order(terms)

    def error_order(self, terms: Any):
        return self.solver.error_order(terms)

    def init(self, terms, t0, t1, y0, args):
        return self.solver.init(terms, t0, t1, y0, args)

    @abc.abstractmethod
    def project(
        self, terms: Any, t1: Any, y1: Any, args: Any
    ) -> tuple[Any, diffrax.RESULTS]:
        """The projected end state, and whether the projection succeeded."""

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        y1, error, dense_info, solver_state, result = self.solver.step(
            terms, t0, t1, y0, args, solver_state, made_jump
        )
        y1, projection_result = self.project(terms, t1, y1, args)
        y1 = match_dtypes(y1, y0)  # a float64 constant in g must not widen the state
        result = diffrax.RESULTS.where(
            result == diffrax.RESULTS.successful, projection_result, result
        )
        if "y1" in dense_info:
            dense_info = {**dense_info, "y1": y1}
        return y1, error, dense_info, solver_state, result

    def func(self, terms, t0, y0, args):
        return self.solver.func(terms, t0, y0, args)
