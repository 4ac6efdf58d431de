r"""How a `Lagrangian` is integrated: the terms, start state and system per solver.

`Lagrangian.integration` (the `AbstractSystem` interface) routes a run by the kind
of solver it is given:

- a general solver (Tsit5, Dopri8, …) integrates (q, q̇) under the Euler–Lagrange
  vector field;
- a symplectic Runge–Kutta method (`GaussLegendre`, `ImplicitMidpoint`) integrates
  (q, p) under Hamilton's equations of the Legendre transform;
- a variational solver (`VariationalMidpoint`) steps (q, p) but discretizes L
  itself, so a force or dissipation is refused;
- with constraints, `Rattle` integrates (q, p) with the constraint forces, and any
  other solver (q, q̇) with q̈ including them (`ConstrainedLagrangianTerm`), from a
  start that must lie on the constraints;
- a splitting method, written for H = T(p) + V(q), is refused by name.

References: the course text §3 and §6.1; Hairer, Lubich & Wanner, *Geometric
Numerical Integration*, 2nd ed. (2006), §VI.6 (variational integrators) and §VII.1
(RATTLE).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import diffrax

from lagjax._core.solver_kinds import AbstractSymplecticRungeKutta, is_partitioned
from lagjax._core.system_protocols import LagrangianLike
from lagjax._core.terms import (
    ConstrainedLagrangianTerm,
    LagrangianTerm,
    LagrangianVectorField,
    RattleTerm,
)
from lagjax.mechanics.constraints import refuse_start_off_constraints
from lagjax.mechanics.legendre_hamiltonian import LegendreHamiltonian


def lagrangian_integration(
    lagrangian: LagrangianLike,
    to_hamiltonian: Callable[[], LegendreHamiltonian],
    solver: Any,
    y0: Any,
    t0: Any,
    args: Any,
) -> Any:
    """`(terms, state0, integrated)` for `lagrangian` and `solver` (module
    docstring); `to_hamiltonian` is its `Lagrangian.to_hamiltonian`."""

    def canonical_start():
        q0, qdot0 = y0
        return (q0, lagrangian.momentum(q0, qdot0, t0, args))

    if lagrangian.constraints is not None:
        y0 = refuse_start_off_constraints(
            lagrangian.constraints, y0[0], y0[1], t0, args
        )
        if solver.term_structure is RattleTerm:
            return RattleTerm(lagrangian), canonical_start(), to_hamiltonian()
        return ConstrainedLagrangianTerm(lagrangian), y0, lagrangian
    if solver.term_structure is LagrangianTerm:
        if lagrangian.force is not None or lagrangian.dissipation is not None:
            raise ValueError(
                f"{type(solver).__name__} discretizes the conservative action only; "
                "this Lagrangian has a force or dissipation. Use GaussLegendre or "
                "an adaptive solver."
            )
        return LagrangianTerm(lagrangian), canonical_start(), to_hamiltonian()
    if isinstance(solver, AbstractSymplecticRungeKutta):
        hamiltonian = to_hamiltonian()
        terms, _, _ = hamiltonian.integration(solver, None, t0, args)
        return terms, canonical_start(), hamiltonian
    if is_partitioned(solver):
        raise ValueError(
            f"{type(solver).__name__} is a splitting method for separable "
            "Hamiltonians H = T(p) + V(q); integrate a Lagrangian with an implicit "
            "symplectic method (GaussLegendre, ImplicitMidpoint) or an adaptive one."
        )
    return diffrax.ODETerm(LagrangianVectorField(lagrangian)), y0, lagrangian
