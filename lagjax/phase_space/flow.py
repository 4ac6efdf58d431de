r"""The flow map of a mechanical system on its flat phase-space vector.

Every phase-space tool needs the same object: the time-$\tau$ map
$\Phi_\tau: y \mapsto y(\tau)$ of an autonomous system, on one flat vector
$y = (q, \dot q)$ for a Lagrangian or $(q, p)$ for a Hamiltonian (the user's state
convention, raveled), differentiable with `jax.jvp` so that its tangent map
$\Phi_\tau'(y)\,v$ is exact. It is built from the public `lj.simulate` only: a fixed
`dt` with the final state saved runs as a `lax.scan` (forward-mode differentiable as
it is); an adaptive run takes diffrax's `ForwardMode` adjoint.

The flow starts every interval at t = 0: the tools assume an autonomous system (the
phase space of a driven system includes the time).
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._core.system import AbstractSystem
from lagjax._integrate.simulate import simulate
from lagjax.phase_space.autonomy import refuse_time_dependence


class PhaseFlow(eqx.Module):
    """How to integrate one system: solver, step, tolerances, and its state's shape.

    `advance(y, duration)` is the flow over `duration` (a multiple of `dt` when `dt`
    is set) on the flat state, `vector_field(y)` its rate; `canonical(y)` gives the
    `(q, p)` a surface of section is written in (p = ∂L/∂q̇ for a Lagrangian). The
    state's layout is kept as static data (tree structure, shapes), so two flows of
    the same system and state shape hit the same `jit` cache entry.
    """

    system: Any
    args: Any
    solver: diffrax.AbstractSolver | None
    dt: float | None = eqx.field(static=True)
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    structure: Any = eqx.field(static=True)
    shapes: tuple[tuple[int, ...], ...] = eqx.field(static=True)

    def unravel(self, y: jax.Array) -> tuple[Any, Any]:
        """The flat state back as the pair (q, q̇ or p) of the user's pytrees."""
        sizes = [math.prod(shape) for shape in self.shapes]
        pieces = jnp.split(y, list(itertools.accumulate(sizes))[:-1])
        leaves = [x.reshape(shape) for x, shape in zip(pieces, self.shapes)]
        return jax.tree_util.tree_unflatten(self.structure, leaves)

    def advance(self, y: jax.Array, duration: float) -> jax.Array:
        adjoint = None if self.dt is not None else diffrax.ForwardMode()
        trajectory = simulate(
            self.system, self.unravel(y), 0.0, duration, dt=self.dt,
            solver=self.solver, args=self.args, rtol=self.rtol, atol=self.atol,
            adjoint=adjoint,
        )  # fmt: skip
        return self._flat_final(trajectory)

    def vector_field(self, y: jax.Array) -> jax.Array:
        """dy/dt on the flat state (Hamilton's or the Euler–Lagrange equations)."""
        q, second = self.unravel(y)
        mechanical, args = resolve_system(self.system, self.args)
        return ravel_pytree(mechanical.state_rate(q, second, 0.0, args))[0]

    def _flat_final(self, trajectory) -> jax.Array:
        second = trajectory.qdot if self.is_lagrangian else trajectory.p
        final = jax.tree_util.tree_map(lambda x: x[-1], (trajectory.q, second))
        return ravel_pytree(final)[0]

    @property
    def is_lagrangian(self) -> bool:
        mechanical, _ = resolve_system(self.system, self.args)
        return not mechanical.second_is_momentum

    def canonical(self, y: jax.Array) -> tuple[Any, Any]:
        """(q, p) of the flat state y."""
        q, second = self.unravel(y)
        mechanical, args = resolve_system(self.system, self.args)
        return q, mechanical.state_momentum(q, second, 0.0, args)


def resolve_system(system: Any, args: Any) -> tuple[Any, Any]:
    """A scene's system and the args it is integrated with (as `simulate` does)."""
    if not isinstance(system, AbstractSystem):
        raise TypeError(
            "Phase-space tools take a lagjax system (a Lagrangian, a Hamiltonian or a "
            f"scene of one); got {type(system).__name__}"
        )
    return system.resolve(args)


def phase_flow(
    system: Any,
    y0: tuple[Any, Any],
    *,
    dt: float | None,
    solver: diffrax.AbstractSolver | None,
    args: Any,
    rtol: float,
    atol: float,
) -> tuple[PhaseFlow, jax.Array]:
    """The `PhaseFlow` of `system` and `y0` as a flat vector; checks the system."""
    mechanical, _ = resolve_system(system, args)
    obstacle = mechanical.phase_space_obstacle()
    if obstacle is not None:
        raise ValueError(obstacle)
    if not (isinstance(y0, tuple) and len(y0) == 2):
        raise ValueError(
            "y0 must be the pair (q0, qdot0) for a Lagrangian or (q0, p0) for a "
            f"Hamiltonian; got {type(y0).__name__}."
        )
    y0 = jax.tree_util.tree_map(jnp.asarray, y0)
    resolved, resolved_args = resolve_system(system, args)
    refuse_time_dependence(resolved, y0, resolved_args)
    flat = ravel_pytree(y0)[0]
    leaves, structure = jax.tree_util.tree_flatten(y0)
    shapes = tuple(tuple(leaf.shape) for leaf in leaves)
    if dt is not None:
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a finite positive number, got {dt}")
    flow = PhaseFlow(system, args, solver, dt, rtol, atol, structure, shapes)
    return flow, flat


def interval_count(t1: float, interval: float, what: str) -> int:
    """How many `interval`s make `t1`; a clear error when it is not a whole number."""
    count = round(t1 / interval)
    if count < 1 or abs(count * interval - t1) > 1e-9 * abs(t1):
        raise ValueError(
            f"t1 = {t1} must be a positive whole multiple of {what} = {interval}; "
            f"choose t1 = {max(count, 1) * interval} or another {what}."
        )
    return count


def resolve_interval(interval: float | None, dt: float | None, t1: float) -> float:
    """The time between tangent renormalisations: a whole number of steps.

    Default: up to 10 steps (the largest step count ≤ 10 that divides t1/dt) when
    `dt` is fixed, t1/1000 for adaptive runs.
    """
    if interval is None:
        if dt is None:
            return t1 / 1000
        steps = interval_count(t1, dt, "dt")
        return dt * max(m for m in range(1, 11) if steps % m == 0)
    interval = float(interval)
    if dt is not None:
        interval_count(interval, dt, "dt")
    return interval
