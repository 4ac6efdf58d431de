"""`RigidBodyTerm`: a diffrax term that carries a `RigidBody` itself.

Any diffrax solver can integrate it as an ordinary ODE term — `vf` is the rigid
body's vector field on `y = (quaternion, body_momentum)` — while the
structure-preserving solvers of `lagjax.solvers.rigid` read the body (its moments
and torque) from it and compose exact sub-flows instead.
"""

from __future__ import annotations

from typing import Any

import diffrax
import jax

from lagjax.precision import match_dtypes

from .body import RigidBody


class RigidBodyTerm(diffrax.AbstractTerm):
    """The term of a rigid body: `vf` is `body.vector_field`, the control is dt."""

    body: RigidBody

    def vf(self, t, y, args):
        quaternion, body_momentum = y
        rates = self.body.vector_field(quaternion, body_momentum, t, args)
        return match_dtypes(rates, y)

    def contr(self, t0, t1, **kwargs):
        del kwargs
        return t1 - t0

    def prod(self, vf, control):
        return jax.tree_util.tree_map(lambda v: v * control, vf)


def unwrap_rigid_body_term(terms: Any) -> tuple[RigidBodyTerm, int]:
    """The `RigidBodyTerm` inside diffrax's time-direction wrappers, and the direction.

    `diffeqsolve` integrates t1 < t0 as forward time in −t by wrapping each term; a
    solver that composes exact flows needs the physical time and step instead.
    """
    direction = 1
    # diffrax's WrapTerm is not public API; it holds `term` and `direction`.
    while not isinstance(terms, RigidBodyTerm):
        inner = getattr(terms, "term", None)
        if inner is None:
            raise ValueError(
                "a rigid-body solver needs a RigidBodyTerm(body), got "
                f"{type(terms).__name__}"
            )
        direction = direction * terms.direction
        terms = inner
    return terms, direction
