r"""float32 against float64 for every scene: what single precision costs.

Each scene of `lagjax.scenes.catalog()` runs twice with its default solver and
step over its default span: once in float64 and once with the scene and its start
cast to float32 (`lagjax._core.precision.cast_floats`; `lj.simulate` then works in
float32 throughout, times included). Rows report

- `error`: the float32 final state's relative distance from the float64 one — the
  round-off of float32 as the dynamics amplifies it (the truncation error is the
  same in both runs and cancels);
- `energy_error`: the float32 run's relative energy error at the end, with the
  energy evaluated in float64 on the float32 state (so it measures the state, not
  float32's evaluation of E);
- `measure`: the float64 run's energy error and the float32/float64 run-time ratio
  (where even float64 changes the energy by > 1e-3 — driven or damped scenes, a
  particle in a frame whose motion is prescribed — the energy columns are left out).

**accurate** means within 1e-3 of the float64 state. Chaotic runs (the double
pendulum, the FPU chain over its default span, the Dzhanibekov flip) cannot
follow one trajectory in float32 and show as *degraded* while their energy error
stays at the float32 level — the physics, not a bug. The rigid bodies also run on
quaternions with `RigidBodyYoshida4`, whose Lie–Poisson rotations keep |L| exact
in float32 too.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
Springer (2006), §VIII.5 (round-off in long integrations); Higham, *Accuracy and
Stability of Numerical Algorithms*, 2nd ed., SIAM (2002), ch. 2.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from benchmarks.stability_engine import Measured, judged_row
from lagjax import diagnostics
from lagjax._core.precision import cast_floats
from lagjax.scenes import catalog
from lagjax.scenes.rigid import SCENES as RIGID_SCENES
from lagjax.solvers.lie_poisson import RigidBodyYoshida4

TOLERANCE = 1e-3
NOT_CONSERVED = 1e-3  # a float64 energy change above this is physics, not error
QUICK_SCENES = ("harmonic-oscillator", "kepler-cartesian", "double-pendulum",
                "torque-free-body", "cartesian-pendulum")  # fmt: skip
QUICK_STEPS = 500  # the quick mode's span, in default steps


@dataclass(frozen=True)
class Route:
    """How a scene is run: a system, its start, its args and the solver."""

    label: str
    system: Any
    y0: Any
    args: Any = None
    solver: Any = None
    energy: Callable[[Any], jax.Array] | None = None  # on the final state, float64


def _narrow(tree: Any) -> Any:
    return cast_floats(jax.tree_util.tree_map(jnp.asarray, tree), jnp.float32)


def _flat(state: Any) -> np.ndarray:
    leaves = jax.tree_util.tree_leaves(state)
    return np.concatenate([np.ravel(np.asarray(x, dtype=np.float64)) for x in leaves])


def _routes(name: str) -> list[Route]:
    scene = catalog()[name]()
    routes = [Route("default solver", scene, scene.initial_state())]
    if isinstance(scene, RIGID_SCENES):  # their second formulation, on quaternions
        routes.append(
            Route("quaternions, RigidBodyYoshida4", scene.rigid_body(),
                  scene.initial_body_state(), args=scene, solver=RigidBodyYoshida4())
        )  # fmt: skip
    return routes


def _final_state(route: Route, y0, system, args, t1, dt):
    """(q, q̇) of a Lagrangian scene, (q, p) otherwise, at t1."""
    trajectory = lj.simulate(system, y0, t1=t1, dt=dt, solver=route.solver, args=args)
    second = trajectory.qdot if _is_lagrangian(route) else trajectory.ys[1]
    return trajectory.q[-1], second[-1]


def _is_lagrangian(route: Route) -> bool:
    system = route.system
    if isinstance(system, lj.scenes.AbstractScene):
        system = system.system()
    return isinstance(system, lj.Lagrangian)


def _measure(route: Route, t1: float, dt: float, timing: dict) -> Measured:
    system, args = route.system, route.args
    wide = diagnostics.time_run(
        lambda y0: _final_state(route, y0, system, args, t1, dt), route.y0, **timing
    )
    narrow_system, narrow_args = _narrow(system), _narrow(args)
    narrow = diagnostics.time_run(
        lambda y0: _final_state(route, y0, narrow_system, narrow_args, t1, dt),
        _narrow(route.y0), **timing,
    )  # fmt: skip
    leaves = jax.tree_util.tree_leaves(narrow.output)
    if any(leaf.dtype != jnp.float32 for leaf in leaves):
        raise TypeError("the float32 run was promoted to float64")
    expected, measured = _flat(wide.output), _flat(narrow.output)
    error = float(np.max(np.abs(measured - expected)) / np.max(np.abs(expected)))
    start_energy = _state_energy(route, route.y0)
    energy32 = abs(_state_energy(route, narrow.output) / start_energy - 1)
    energy64 = abs(_state_energy(route, wide.output) / start_energy - 1)
    ratio = narrow.run_seconds / wide.run_seconds
    measure = f"float64 energy error {energy64:.1e}; float32 run {ratio:.2f}× float64"
    if energy64 > NOT_CONSERVED:  # driven, damped, or a moving frame's Jacobi h
        energy32 = math.nan
        measure = f"energy not conserved here; float32 run {ratio:.2f}× float64"
    return Measured(
        error, narrow.run_seconds, narrow.compile_seconds, energy32, measure
    )


def _state_energy(route: Route, state) -> float:
    """H or the Jacobi integral of one state, in float64, from the system itself."""
    wide = cast_floats(jax.tree_util.tree_map(jnp.asarray, state), jnp.float64)
    system, args = route.system, route.args
    if isinstance(system, lj.scenes.AbstractScene):
        system, args = system.system(), system
    q, second = wide
    if isinstance(system, lj.Lagrangian):
        return float(system.energy(q, second, 0.0, args))
    return float(system(q, second, 0.0, args))


@dataclass
class PrecisionStudy:
    """Every scene (quick: five) in float32 against float64."""

    quick: bool
    name: str = "float32 vs float64"

    def rows(self, timing: dict) -> Iterator[dict]:
        names = QUICK_SCENES if self.quick else tuple(catalog())
        for scene_name in names:
            scene_class = catalog()[scene_name]
            dt = scene_class.default_dt
            t1 = QUICK_STEPS * dt if self.quick else scene_class.default_t1
            for route in _routes(scene_name):
                yield judged_row(
                    f"float32 vs float64: {scene_name}", route.label, TOLERANCE,
                    lambda route=route, t1=t1, dt=dt: _measure(route, t1, dt, timing),
                )  # fmt: skip


def precision_study(quick: bool) -> PrecisionStudy:
    return PrecisionStudy(quick)
