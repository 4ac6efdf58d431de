"""The kinds of solver a system tells apart, and the default methods it may ask for.

A system builds different diffrax terms for different kinds of solver: a splitting
method gets the (drift, kick) pair of a separable H, a symplectic implicit
Runge–Kutta method gets Hamilton's equations of a Lagrangian's Legendre transform,
and a constrained Lagrangian accepts only solvers that keep its constraints. The
systems dispatch on these abstract kinds; the concrete solvers in `lagjax.solvers`
subclass them. So neither imports the other.

A system does not name its default solver either: it names a `DefaultMethod`, and
`lagjax._integrate.solver_choice` (above both systems and solvers) turns that into
a solver.
"""

from __future__ import annotations

import enum
from typing import ClassVar

import diffrax


def is_partitioned(solver: diffrax.AbstractSolver) -> bool:
    """True for solvers that step (q, p) with two terms (splitting methods)."""
    structure = solver.term_structure
    return isinstance(structure, tuple) and len(structure) == 2


class AbstractSplittingMethod(diffrax.AbstractSolver):
    """A splitting method for H = T(p) + V(q), stepping the (drift, kick) terms."""

    # Runge–Kutta–Nyström tables keep their order only when T is quadratic in p;
    # the system refuses them otherwise (SeparableHamiltonian.integration).
    needs_quadratic_kinetic: ClassVar[bool] = False


class AbstractSymplecticRungeKutta(diffrax.AbstractSolver):
    """A symplectic implicit Runge–Kutta method on one term of Hamilton's equations;
    a Lagrangian is integrated on the (q, p) of its Legendre transform."""


class AbstractConstraintKeeping(diffrax.AbstractSolver):
    """A solver that keeps a constrained Lagrangian on its constraints (a projection
    after each step, or RATTLE)."""


class AbstractTimeReversible(diffrax.AbstractSolver):
    r"""A symmetric one-step method: $\Phi_{-h} = \Phi_h^{-1}$, so the state at
    step k − 1 is recomputed from step k by a step of −h (exactly, up to
    round-off).

    The reversible adjoint (`lagjax.ReversibleAdjoint`) accepts exactly these
    solvers. A method is symmetric when its coefficients are (a palindromic
    splitting, a symmetric collocation method); a subclass whose symmetry depends
    on its tables says so in `is_time_reversible`.

    ??? cite "References"

        - Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
          Springer (2006), §V.1 (symmetric methods), §V.2 (symmetric
          Runge–Kutta methods), §V.3 (symmetric composition).
    """

    def is_time_reversible(self) -> bool:
        """Whether this instance's step is symmetric (default: every instance)."""
        return True

    def is_bit_reversible(self) -> bool:
        """Whether a step of −h undoes a step of h to the last bit, not only up to
        round-off (an integer-lattice splitting; default: no)."""
        return False


class DefaultMethod(enum.Enum):
    """The method a system asks for when the caller names no solver."""

    ADAPTIVE = "adaptive Runge–Kutta (Tsit5)"
    ADAPTIVE_UNIT_QUATERNION = (
        "adaptive Runge–Kutta, quaternion projected to unit length"
    )
    SYMPLECTIC_RUNGE_KUTTA = "Gauss–Legendre, 2 stages (implicit, symplectic, order 4)"
    SPLITTING = "Yoshida4 (explicit splitting, symplectic, order 4)"
    LIE_POISSON = "Lie–Poisson splitting of a rigid body (RigidBodyYoshida4)"
