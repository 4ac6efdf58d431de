r"""A tool that needs a Lagrangian takes a Lagrangian, or says how to get one.

Normal modes and equilibria expand $L(q, \dot q)$ about a configuration: they need
the kinetic matrix $\partial^2 L/\partial\dot q^2$ and the potential's curvature
in generalized coordinates. A scene whose system is a Lagrangian is taken with
itself as `args` (as `simulate` takes it); a Hamiltonian (whose Legendre transform
`ham.to_lagrangian()` is the Lagrangian), a rigid body (whose state is an
orientation, not coordinates) and a bare function are refused by name, with the
call that gets a Lagrangian or the tool that takes the system as it is
(`lj.linearize`).

References: the course text §5 (small oscillations need T and V as quadratic
forms in the generalized velocities and coordinates); Goldstein, *Classical
Mechanics* §8.1 (the Legendre transform between L and H).
"""

from __future__ import annotations

from typing import Any

from lagjax._core.system import AbstractSystem
from lagjax.mechanics.abstract_hamiltonian import AbstractHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian


def as_lagrangian(system: Any, args: Any, caller: str) -> tuple[Lagrangian, Any]:
    """`(lagrangian, args)` from what the caller passed to `caller`; anything that
    is not a Lagrangian (or a scene of one) raises `TypeError` with the remedy."""
    given = type(system).__name__
    if isinstance(system, AbstractSystem) and not isinstance(system, Lagrangian):
        system, args = system.resolve(args)  # a scene: its system and itself
    if isinstance(system, Lagrangian):
        return system, args
    kind = type(system).__name__
    what = given if given == kind else f"{given}, whose system is a {kind}"
    if isinstance(system, AbstractHamiltonian):
        name = "ham" if given == kind else "scene.system()"
        remedy = (
            f"pass its Legendre transform, {name}.to_lagrangian()"
            + ("" if given == kind else " with args=scene")
            + ", or use lj.linearize(system, (q_eq, p_eq), args) for the "
            "eigenvalues of the linearized flow"
        )
    elif isinstance(system, AbstractSystem):
        remedy = (
            "its state is not a set of generalized coordinates with velocities; "
            "write its Lagrangian in coordinates (a rigid body in Euler angles: "
            "lj.scenes.HeavySymmetricTop().system()), or use lj.linearize(system, "
            "state, args) for the eigenvalues about a steady motion"
        )
    elif callable(system):
        remedy = "wrap the function: lj.Lagrangian(L)"
    else:
        remedy = "pass lj.Lagrangian(L) for a function L(q, qdot)"
    raise TypeError(
        f"{caller} takes a lagjax Lagrangian (small oscillations of L(q, q̇) about "
        f"an equilibrium), got a {what}: {remedy}"
    )
