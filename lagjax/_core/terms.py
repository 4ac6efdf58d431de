"""diffrax terms that carry a mechanical system, and the vector fields of the others.

A solver that needs more than a vector field — a variational integrator needs L, a
RATTLE step the constraints, a Lie–Poisson splitting the rigid body — reads the
system from its term. Every such term is an `AbstractSystemTerm`: its control is
the time step and its `vf` is the system's ordinary vector field, so any diffrax
utility that evaluates a term still works. Solvers that only need a vector field
get a plain `diffrax.ODETerm` of one of the vector fields below.

The vector fields are equinox Modules rather than closures on purpose: two fields
of the same system compare equal and hash alike, so compiled functions are reused
across calls. Each returns its derivative in the dtype of the state
(`lagjax._core.precision`), so a float32 run stays float32.

diffrax integrates t1 < t0 as forward time in −t by wrapping each term;
`unwrap_term` and `physical_step` undo that for solvers that compose exact flows
or discretize the action and therefore need the physical time and step.
"""

from __future__ import annotations

import abc
from typing import Any, TypeVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._core.precision import match_dtypes
from lagjax._core.system_protocols import (
    HamiltonianLike,
    LagrangianLike,
    RigidBodyLike,
    SeparableLike,
)


class AbstractSystemTerm(diffrax.AbstractTerm):
    """A term whose control is the time step and whose `vf` is a system's vector field."""

    @abc.abstractmethod
    def vf(self, t, y, args):
        """The time derivative of the state `y`."""

    def contr(self, t0, t1, **kwargs):
        del kwargs
        return t1 - t0

    def prod(self, vf, control):
        return jax.tree_util.tree_map(lambda v: v * control, vf)


class LagrangianTerm(AbstractSystemTerm):
    """The term of a `Lagrangian` on `y = (q, p)`, for variational solvers.

    `vf` gives Hamilton's equations of the Legendre-transformed system; variational
    solvers (`VariationalMidpoint`) discretize `lagrangian` directly.
    """

    lagrangian: LagrangianLike

    def vf(self, t, y, args):
        q, p = y
        return self.lagrangian.to_hamiltonian().vector_field(q, p, t, args)


class ConstrainedLagrangianTerm(AbstractSystemTerm):
    """The term of a constrained `Lagrangian` on `y = (q, q̇)`.

    `vf` is `(q̇, q̈)` with q̈ including the constraint forces, so any diffrax solver
    integrates it; `ConstraintProjection` reads the constraints from it.
    """

    lagrangian: LagrangianLike

    def vf(self, t, y, args):
        q, qdot = y
        qddot = self.lagrangian.acceleration(q, qdot, t, args, check=False)
        return qdot, match_dtypes(qddot, qdot)


class RattleTerm(AbstractSystemTerm):
    r"""The term of a holonomically constrained `Lagrangian` on `y = (q, p)`.

    `vf` is $(\dot q, \dot p) = (M^{-1}p, \partial L/\partial q + G^T\lambda)$;
    `Rattle` reads L and g from it.
    """

    lagrangian: LagrangianLike

    def vf(self, t, y, args):
        q, p = y
        qdot = self.lagrangian.to_hamiltonian().velocity(q, p, t, args)
        gradient = jax.grad(self.lagrangian, argnums=0)(q, qdot, t, args)
        force = self.lagrangian.constraint_force(q, qdot, t, args)
        return qdot, jax.tree_util.tree_map(jnp.add, gradient, force)


class RigidBodyTerm(AbstractSystemTerm):
    """The term of a `RigidBody` on `y = (quaternion, body_momentum)`.

    `vf` is the body's vector field; the Lie–Poisson splittings
    (`lagjax.solvers.lie_poisson`) read the moments and torque from `body` and
    compose exact sub-flows instead.
    """

    body: RigidBodyLike

    def vf(self, t, y, args):
        quaternion, body_momentum = y
        rates = self.body.vector_field(quaternion, body_momentum, t, args)
        return match_dtypes(rates, y)


_Term = TypeVar("_Term", bound=AbstractSystemTerm)


def unwrap_term(terms: Any, kind: type[_Term]) -> tuple[_Term, Any]:
    """The term of type `kind` inside diffrax's time-direction wrappers, and the
    direction (+1, or −1 when diffrax runs t1 < t0 in reversed time)."""
    direction = 1
    # diffrax's WrapTerm is not public API; it holds `term` and `direction`.
    while not isinstance(terms, kind):
        inner = getattr(terms, "term", None)
        if inner is None:
            raise ValueError(
                f"this solver needs a {kind.__name__}, got {type(terms).__name__}"
            )
        direction = direction * terms.direction
        terms = inner
    return terms, direction


def time_direction(terms: Any) -> Any:
    """+1, or −1 when diffrax integrates t1 < t0 in reversed time: the product of
    the directions of the wrappers around the first term (diffrax wraps every term
    alike; its `WrapTerm` is not public API, so it is read by its `term` and
    `direction` attributes, as in `unwrap_term`)."""
    term = jax.tree_util.tree_leaves(
        terms, is_leaf=lambda x: isinstance(x, diffrax.AbstractTerm)
    )[0]
    direction = 1
    while getattr(term, "term", None) is not None and hasattr(term, "direction"):
        direction = direction * term.direction
        term = term.term
    return direction


def physical_step(
    terms: Any, kind: type[_Term], t0: Any, t1: Any
) -> tuple[_Term, Any, Any]:
    """`(term, start, h)`: the unwrapped term, the physical start time and signed step."""
    term, direction = unwrap_term(terms, kind)
    return term, direction * t0, direction * (t1 - t0)


class LagrangianVectorField(eqx.Module):
    """(q̇, q̈) on the state (q, q̇), q̈ from the Euler–Lagrange equations."""

    system: LagrangianLike

    def __call__(self, t: Any, y: tuple[Any, Any], args: Any) -> tuple[Any, Any]:
        q, qdot = y
        # No per-evaluation singularity branch in the hot loop: simulate checks the
        # saved states once (see `euler_lagrange_acceleration`'s `check`).
        qddot = self.system.acceleration(q, qdot, t, args, check=False)
        return qdot, match_dtypes(qddot, qdot)


class HamiltonVectorField(eqx.Module):
    """(q̇, ṗ) = (∂H/∂p, −∂H/∂q) on the state (q, p)."""

    system: HamiltonianLike

    def __call__(self, t: Any, y: tuple[Any, Any], args: Any) -> tuple[Any, Any]:
        return match_dtypes(self.system.vector_field(y[0], y[1], t, args), y)


class SeparableDrift(eqx.Module):
    """dq/dt = ∂T/∂p as a function of p (the first term of a splitting method)."""

    system: SeparableLike

    def __call__(self, t: Any, p: Any, args: Any) -> Any:
        return match_dtypes(self.system.velocity(None, p, t, args), p)


class SeparableKick(eqx.Module):
    """dp/dt = −∂V/∂q as a function of q (the second term of a splitting method)."""

    system: SeparableLike

    def __call__(self, t: Any, q: Any, args: Any) -> Any:
        return match_dtypes(self.system.potential_force(q, t, args), q)
