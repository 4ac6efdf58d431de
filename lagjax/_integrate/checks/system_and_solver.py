"""Refuse a `simulate` call whose system or solver is the wrong kind of object,
or whose solver does not fit its system, naming the remedy (the first rows of
`lagjax._integrate.checks.inputs`' table).

A bare function, a class or a string where an instance belongs; an SDE or IMEX
solver (diffrax's `MultiTerm` solvers), which needs terms `simulate` does not
make; a solver written for one kind of system given another (each system's
`refuse_solver` says which).
"""

from __future__ import annotations

import typing
from typing import Any

import diffrax

from lagjax._core.system import AbstractSystem

_IMEX_SOLVERS = (diffrax.KenCarp3, diffrax.KenCarp4, diffrax.KenCarp5, diffrax.Sil3)


def user_system(system: Any) -> Any:
    """The system whose convention `y0` follows (a scene's `system()`)."""
    return system.resolve(None)[0]


def check_system(system: Any) -> None:
    """`system` must be a lagjax system instance."""
    if isinstance(system, AbstractSystem):
        return
    if isinstance(system, type) and issubclass(system, AbstractSystem):
        raise TypeError(
            f"system is the class {system.__name__}, not an instance: pass "
            f"{system.__name__}(...) (a scene: {system.__name__}() for its defaults)"
        )
    if callable(system):
        raise TypeError(
            "system is a plain function; simulate needs a lagjax system: wrap it as "
            "lagjax.Lagrangian(L) for L(q, qdot) or lagjax.Hamiltonian(H) for "
            "H(q, p) (or pick a scene from lagjax.scenes)"
        )
    raise TypeError(
        f"system must be a lagjax system (Lagrangian, Hamiltonian, "
        f"SeparableHamiltonian, RigidBody or a scene), got {type(system).__name__}"
    )


def check_solver(solver: Any) -> None:
    """`solver` must be None or an ODE solver instance (not a class or a name)."""
    if solver is None:
        return
    if isinstance(solver, str):
        raise TypeError(
            f"solver must be a solver object, not the string {solver!r}: pass an "
            "instance such as diffrax.Tsit5() or lagjax.Yoshida4()"
        )
    if isinstance(solver, type):
        raise TypeError(
            f"solver is the class {solver.__name__}, not an instance: pass "
            f"{solver.__name__}() (with its arguments, if any)"
        )
    if not isinstance(solver, diffrax.AbstractSolver):
        raise TypeError(
            f"solver must be a diffrax or lagjax solver instance, got "
            f"{type(solver).__name__}"
        )
    if typing.get_origin(solver.term_structure) is diffrax.MultiTerm:
        name = type(solver).__name__
        if isinstance(solver, _IMEX_SOLVERS):
            raise TypeError(
                f"{name} is an IMEX solver: it needs the vector field split into "
                "explicit and implicit terms, which simulate does not make. For a "
                "stiff system use diffrax.Kvaerno5() (with dt=None)"
            )
        raise TypeError(
            f"{name} is a stochastic (SDE) solver: it needs a diffusion term driven "
            "by Brownian motion, and lagjax integrates deterministic equations of "
            "motion. Use an ODE solver: diffrax.Tsit5(), diffrax.Dopri8() or a "
            "symplectic lagjax solver"
        )


def check_solver_fits(system: Any, solver: Any) -> None:
    """Solvers written for one kind of system refuse the others by name."""
    if solver is not None:
        system.refuse_solver(solver)
