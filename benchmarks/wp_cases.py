r"""The scenes of the work-precision report: what runs, for how long, swept how.

A `Case` is one scene of the report — its run length, the fixed-step solvers with
their step counts, the adaptive ones with their tolerances, and the peer
(`peers.py`) that stands beside it. `build_cases` lays the table out by hand, one
scene or one sweep per line; `--quick` keeps two scenes with two points a line.
Cases compare runs through a flat "comparable" state: (q, q̇) for most scenes,
(R, ω) for the rigid body, whose peers use other coordinates.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
§I.2 (Hénon–Heiles), §I.5 (Fermi–Pasta–Ulam).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from benchmarks import peers
from lagjax.rigid import quaternion_to_matrix
from lagjax.scenes.base import AbstractScene
from lagjax.scenes.central import KeplerCartesian
from lagjax.scenes.chains import FermiPastaUlamChain
from lagjax.scenes.earth import FoucaultPendulum
from lagjax.scenes.pendulums import DoublePendulum, SimplePendulum
from lagjax.scenes.rigid import TorqueFreeBody
from lagjax.solvers.lie_poisson import (
    QuaternionProjection,
    RigidBodyVerlet,
    RigidBodyYoshida4,
)


class HenonHeiles(AbstractScene):
    r"""Hénon–Heiles, $H = \tfrac12|p|^2 + \tfrac12(x^2 + y^2) + x^2y - y^3/3$.

    From q = (0.1, 0), p = (0, 0.5): E = 0.13 < 1/6, a bounded orbit (GNI §I.2).
    """

    default_t1: ClassVar[float] = 100.0
    default_dt: ClassVar[float] = 0.01

    def system(self) -> lj.SeparableHamiltonian:
        return lj.SeparableHamiltonian(
            lambda p, t, args: 0.5 * jnp.sum(p**2),
            lambda q, t, args: (
                0.5 * (q[0] ** 2 + q[1] ** 2) + q[0] ** 2 * q[1] - q[1] ** 3 / 3
            ),
        )

    def initial_state(self):
        return jnp.array([0.1, 0.0]), jnp.array([0.0, 0.5])


def comparable(q: Any, qdot: Any) -> jax.Array:
    return jnp.concatenate([jnp.ravel(q), jnp.ravel(qdot)])


def position_and_velocity(trajectory: Any) -> jax.Array:
    return jax.vmap(comparable)(trajectory.q, trajectory.qdot)


def rotation_and_angular_velocity(trajectory: Any) -> jax.Array:
    """(R, ω) of a `RigidBody` run on (quaternion, body momentum Π)."""
    rotation = quaternion_to_matrix(trajectory.q).reshape(-1, 9)
    return jnp.concatenate([rotation, trajectory.ys[1] / trajectory.system.moments], -1)


@dataclass
class Case:
    """A scene, its run length, its sweeps and the peer that stands beside it."""

    key: str
    title: str
    scene: Any
    t1: float
    fixed: dict[str, tuple[Any, tuple[int, ...]]]
    adaptive: dict[str, tuple[Any, tuple[float, ...]]]
    peer: peers.Peer
    peer_tolerances: tuple[float, ...]
    scipy_methods: tuple[str, ...] = ("DOP853",)
    exact: np.ndarray | None = None
    system: Any = None  # what lj.simulate integrates; default the scene
    states: Callable[[Any], jax.Array] = position_and_velocity
    initial_state: Any = None

    def start(self) -> Any:
        return (
            self.scene.initial_state()
            if self.initial_state is None
            else self.initial_state
        )


# fmt: off
# The case table is laid out by hand: one scene, or one sweep, per line.
SOLVERS = {
    "StormerVerlet": lj.StormerVerlet(), "Yoshida4": lj.Yoshida4(), "KahanLi8": lj.KahanLi8(),
    "GaussLegendre(2)": lj.GaussLegendre(stages=2), "GaussLegendre(3)": lj.GaussLegendre(stages=3),
    "RigidBodyVerlet": RigidBodyVerlet(), "RigidBodyYoshida4": RigidBodyYoshida4(),
    "Tsit5": diffrax.Tsit5(), "Dopri8": diffrax.Dopri8(), "Kvaerno5": diffrax.Kvaerno5(),
    "QuaternionProjection(Dopri8)": QuaternionProjection(diffrax.Dopri8()),
}
# Step counts over the whole run, coarse to fine.
SPLITTING = {"StormerVerlet": (2e3, 8e3, 3.2e4, 1.28e5), "Yoshida4": (1e3, 3e3, 1e4, 3e4),
             "KahanLi8": (500, 1e3, 2e3, 4e3)}
IMPLICIT = {"GaussLegendre(2)": (1e3, 2e3, 4e3, 8e3), "GaussLegendre(3)": (500, 1e3, 2e3, 4e3)}
RIGID = {"RigidBodyVerlet": SPLITTING["StormerVerlet"], "RigidBodyYoshida4": SPLITTING["Yoshida4"]}
NON_STIFF = ("Tsit5", "Dopri8")


def _case_maker(quick: bool, tolerances: tuple[float, ...]) -> Callable[..., Case]:
    """`case(key, title, scene, t1, fixed, adaptive, peer, **kwargs)`: the sweeps of
    the named solvers, cut down to two points a line when quick."""

    def case(key, title, scene, t1, fixed, adaptive, peer, peer_tolerances=tolerances,
             **kwargs) -> Case:
        steps = {k: tuple(int(n) for n in v) for k, v in fixed.items()}
        lines = {k: (SOLVERS[k], v[:2] if quick else v) for k, v in steps.items()}
        sweeps = {k: (SOLVERS[k], tolerances[:3] if k == "Kvaerno5" else tolerances) for k in adaptive}
        return Case(key, title, scene, t1, lines, sweeps, peer, peer_tolerances, **kwargs)

    return case


def _quick_cases(case: Callable[..., Case], quick: bool) -> list[Case]:
    """Kepler and the double pendulum: the two scenes of a quick run too."""
    kepler, periods = KeplerCartesian(eccentricity=jnp.asarray(0.6)), 10 if quick else 100
    t1 = periods * float(kepler.period())
    orbit = np.concatenate([np.asarray(x) for x in kepler.orbit_state(jnp.asarray(t1))])
    per_orbit = {"StormerVerlet": (1e3, 4e3, 1.6e4, 6.4e4),
                 "Yoshida4": () if quick else (300, 1e3, 3e3, 1e4),
                 "KahanLi8": () if quick else (200, 400, 800, 1600)}
    kepler_lines = {k: tuple(periods * n for n in v) for k, v in per_orbit.items() if v}
    double = DoublePendulum()
    double_lines = {k: IMPLICIT[k] for k in IMPLICIT if not quick or k == "GaussLegendre(2)"}
    # Quick runs the peers (each point a compilation, SymPy a derivation) on the
    # double pendulum only, where the routes are compared.
    no_peer_points = dict(peer_tolerances=()) if quick else {}
    return [
        case("kepler", f"Kepler e = 0.6, {periods} periods", kepler, t1, kepler_lines,
             NON_STIFF[: 1 if quick else 2], peers.kepler(kepler), exact=orbit,
             **no_peer_points),
        case("double_pendulum", "Double pendulum from (2, 2.5) rad, t = 5 s", double, 5.0,
             double_lines, NON_STIFF[1:] if quick else NON_STIFF, peers.double_pendulum(double)),
    ]


def _full_cases(case: Callable[..., Case]) -> list[Case]:
    """The scenes only a full run has."""
    pendulum, stiff = SimplePendulum(), FermiPastaUlamChain(frequency=50.0)
    foucault, body, henon = FoucaultPendulum(), TorqueFreeBody(), HenonHeiles()
    return [
        case("pendulum", "Pendulum at 150°, 10 periods", pendulum, 10 * float(pendulum.period()),
             SPLITTING, NON_STIFF, peers.pendulum(pendulum),
             exact=np.array([float(pendulum.amplitude), 0.0])),
        case("henon_heiles", "Hénon–Heiles, E = 0.13, t = 100", henon, 100.0,
             SPLITTING, NON_STIFF, peers.henon_heiles(henon)),
        case("fpu", "Stiff FPU chain, ω = 50, t = 20", stiff, 20.0,
             {k: SPLITTING[k] for k in ("StormerVerlet", "Yoshida4")}, (*NON_STIFF, "Kvaerno5"),
             peers.fermi_pasta_ulam(stiff), scipy_methods=("DOP853", "LSODA", "Radau")),
        case("foucault", "Foucault pendulum at 45°, t = 100 s", foucault, 100.0,
             IMPLICIT, NON_STIFF, peers.foucault(foucault)),
        case("rigid", "Free asymmetric rigid body, I = (1, 2, 3), t = 20", body, 20.0,
             RIGID, ("QuaternionProjection(Dopri8)",), peers.free_rigid_body(body),
             system=body.rigid_body(), states=rotation_and_angular_velocity,
             initial_state=body.initial_body_state()),
    ]
# fmt: on


def build_cases(quick: bool) -> list[Case]:
    """The scenes of the report; quick keeps two of them, with two points a line."""
    tolerances = (1e-5, 1e-8) if quick else (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
    case = _case_maker(quick, tolerances)
    cases = _quick_cases(case, quick)
    return cases if quick else [*cases, *_full_cases(case)]
