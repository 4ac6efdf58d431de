"""Vector fields of mechanical systems as diffrax-ready callables.

`simulate` wraps these in `diffrax.ODETerm`. They are equinox Modules rather than
closures on purpose: two fields of the same system compare equal and hash alike, so
diffrax's and lagjax's compiled functions are reused across calls instead of being
recompiled for every new closure. Each returns its derivative in the dtype of the
state (`lagjax.precision`), so a float32 run stays float32.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx

from .mechanics.hamiltonian import AbstractHamiltonian, SeparableHamiltonian
from .mechanics.lagrangian import Lagrangian
from .precision import match_dtypes


class LagrangianVectorField(eqx.Module):
    """(q̇, q̈) on the state (q, q̇), q̈ from the Euler–Lagrange equations."""

    system: Lagrangian

    def __call__(self, t: Any, y: tuple[Any, Any], args: Any) -> tuple[Any, Any]:
        q, qdot = y
        # No per-evaluation singularity branch in the hot loop: simulate checks the
        # saved states once (see `euler_lagrange_acceleration`'s `check`).
        qddot = self.system.acceleration(q, qdot, t, args, check=False)
        return qdot, match_dtypes(qddot, qdot)


class HamiltonVectorField(eqx.Module):
    """(q̇, ṗ) = (∂H/∂p, −∂H/∂q) on the state (q, p)."""

    system: AbstractHamiltonian

    def __call__(self, t: Any, y: tuple[Any, Any], args: Any) -> tuple[Any, Any]:
        return match_dtypes(self.system.vector_field(y[0], y[1], t, args), y)


class SeparableDrift(eqx.Module):
    """dq/dt = ∂T/∂p as a function of p (the first term of a splitting method)."""

    system: SeparableHamiltonian

    def __call__(self, t: Any, p: Any, args: Any) -> Any:
        return match_dtypes(self.system.velocity(None, p, t, args), p)


class SeparableKick(eqx.Module):
    """dp/dt = −∂V/∂q as a function of q (the second term of a splitting method)."""

    system: SeparableHamiltonian

    def __call__(self, t: Any, q: Any, args: Any) -> Any:
        return match_dtypes(self.system.potential_force(q, t, args), q)
