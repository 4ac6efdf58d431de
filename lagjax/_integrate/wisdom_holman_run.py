r"""`simulate` with `lj.WisdomHolman`: a planetary system stepped in Jacobi coordinates.

At the boundary the user's inertial $(q, p)$ become Jacobi coordinates
(`lagjax.solvers.wisdom_holman.to_jacobi`), the corrector's inverse takes them to
the mapping coordinates, $y \mapsto C^{-1}(y)$, and the loop runs the leapfrog with
its half drifts merged:

$$u_0 = D_{h/2}\,y_0,\qquad u_{n+1} = D_h K_h\,u_n,\qquad y_n = D_{-h/2}\,u_n$$

(one Kepler drift and one kick per step; $y_n = \Phi_h^n y_0$ exactly as the
synchronised step computes it). A saved state is $C(y_n)$ back in inertial
coordinates. Saves lie on the step grid $t_0 + k\,h$: the corrector and the
method's error belong to one step size, so a save between steps would need a
different map; a time off the grid is refused with the step that would reach it.

The loop runs the exact step count as nested `lax.scan`s — the steps to the
first save, then one inner scan per save interval, whose outputs are the $u_k$ to
save (`jit`, `vmap`, `jax.jvp`, `jax.grad`; save times at uneven spacings take an
inner loop of the gap's length, forward mode only) — and synchronises the saved
states after the loop. A Kepler drift that does not
converge, or a non-finite state, ends the run: the saves from that step on are NaN
and `traj.result` says why (an error unless `throw=False`).

References: Wisdom & Holman, AJ 102, 1528 (1991); Wisdom, Holman & Touma, Fields
Inst. Commun. 10, 217 (1996); Rein & Tamayo, MNRAS 452, 376 (2015).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from lagjax._core.precision import cast_floats, working_dtype
from lagjax._integrate.checks.inputs import check_simulate_inputs
from lagjax.solvers.wisdom_holman import (
    RESULTS,
    GravitatingBodies,
    KeplerInteractionTerm,
    WisdomHolman,
    to_inertial,
    to_jacobi,
)
from lagjax.trajectory import Trajectory

_GRID_TOLERANCE = 1e-9  # of a step: a save time this close to t0 + k·dt is on it


def run_wisdom_holman(
    system: Any, y0: Any, t0: Any, t1: Any, dt: Any, solver: WisdomHolman,
    ts: Any, args: Any, max_steps: int | None, throw: bool, **options: Any,
) -> Trajectory:  # fmt: skip
    """`simulate` for a `WisdomHolman` solver: the checks, the run, the verdict."""
    given = [name for name, value in options.items() if value not in (None, False)]
    if given:
        raise ValueError(
            f"{solver.name} does not support {', '.join(given)}: it saves the states "
            "at the times ts=... on its step grid t0 + k·dt"
        )
    if t1 is None:
        t1 = system.default_span()[0]
    t0, t1, dt = _static_times(t0, t1, dt, solver)
    y0 = check_simulate_inputs(system, y0, t0, t1, dt, None, ts, args, max_steps)
    system, args = system.resolve(args)
    if not isinstance(args, GravitatingBodies):
        raise TypeError(
            f"{solver.name} integrates gravitating bodies: pass a "
            "lagjax.scenes.PlanetarySystem (or args with masses and "
            f"gravitational_constant); got args of type {type(args).__name__}"
        )
    dtype = working_dtype(y0)
    y0, args = cast_floats(y0, dtype), cast_floats(args, dtype)
    _check_bodies(args, y0, solver)
    save_ts = np.reshape(np.asarray(t1 if ts is None else ts, dtype=float), (-1,))
    save_steps = _save_steps(save_ts, t0, dt, solver)
    steps = int(save_steps.max())
    if max_steps is not None and steps > max_steps:
        raise ValueError(
            f"{solver.name}: the last save time needs {steps} steps of dt = {dt:g}, "
            f"more than max_steps = {max_steps}; raise max_steps or pass a larger dt"
        )
    distinct, slot_of_save = np.unique(save_steps, return_inverse=True)
    trajectory = _compiled_run(
        system, args, y0, solver, jnp.asarray(dt, dtype), steps,
        tuple(int(k) for k in distinct), tuple(int(i) for i in slot_of_save),
        jnp.asarray(save_ts, dtype), throw,
    )  # fmt: skip
    return trajectory


def _static_times(t0: Any, t1: Any, dt: Any, solver: WisdomHolman):
    """t0, t1, dt as Python floats: the step count fixes the loop's length."""
    if dt is None:
        raise ValueError(
            f"{solver.name} takes fixed steps: pass dt (a twentieth of the innermost "
            "orbit's period or less; 10 days for the outer solar system)"
        )
    if any(isinstance(value, Tracer) for value in (t0, t1, dt)):
        raise TypeError(
            f"{solver.name} needs t0, t1 and dt as numbers, not traced values: the "
            "number of steps is the length of its compiled loop"
        )
    t0, t1, dt = float(t0), float(t1), float(dt)
    if not dt > 0:
        raise ValueError(f"{solver.name}: the step dt must be positive; got {dt}")
    if not t1 > t0:
        raise ValueError(
            f"{solver.name} integrates forward: t1 = {t1} must exceed t0 = {t0} "
            "(for the past, reverse the momenta)"
        )
    return t0, t1, dt


def _check_bodies(bodies: Any, y0: Any, solver: WisdomHolman) -> None:
    """A positive central mass and G, one row of y0 per mass; traced values are
    checked when the compiled run starts (`_compiled_run`)."""
    masses = bodies.masses
    if jnp.ndim(masses) != 1 or jnp.shape(masses)[0] < 2:
        raise ValueError(
            f"{solver.name} needs masses of shape (N,) with N ≥ 2 bodies (the star "
            f"first); got shape {jnp.shape(masses)}"
        )
    for part, name in zip(y0, ("positions q0", "momenta p0")):
        if jnp.shape(part) != (jnp.shape(masses)[0], 3):
            raise ValueError(
                f"{solver.name}: {name} must have shape (N, 3) = "
                f"({jnp.shape(masses)[0]}, 3), one row per mass; got {jnp.shape(part)}"
            )
    if isinstance(masses, Tracer):
        return
    masses = np.asarray(masses)
    central = float(masses[0])
    if not central > 0 or not np.all(masses > 0):
        raise ValueError(
            f"{solver.name}: the central mass masses[0] = {central:g} and every "
            f"other mass must be positive; got masses = {np.asarray(masses)}"
        )
    gravity = bodies.gravitational_constant
    if not isinstance(gravity, Tracer) and not float(gravity) > 0:
        raise ValueError(
            f"{solver.name}: the gravitational constant must be positive; got "
            f"{float(gravity)}"
        )


def _save_steps(save_ts: np.ndarray, t0: float, dt: float, solver) -> np.ndarray:
    """The step index k of each save time t0 + k·dt; off-grid times refused."""
    positions = (save_ts - t0) / dt
    steps = np.round(positions)
    off = np.abs(positions - steps) > _GRID_TOLERANCE * np.maximum(1, np.abs(steps))
    if np.any(off) or np.any(steps < 0) or not np.all(np.isfinite(save_ts)):
        bad = float(save_ts[np.argmax(off | (steps < 0) | ~np.isfinite(save_ts))])
        raise ValueError(
            f"{solver.name} saves on its step grid t0 + k·dt (t0 = {t0:g}, dt = "
            f"{dt:g}); {bad:g} is not on it. Pass save times on the grid, or a dt "
            "that divides the spacing of ts (the corrector and the error of the "
            "map belong to one step size)"
        )
    return steps.astype(np.int64)


class _Carry(NamedTuple):
    u: Any  # the state half a drift ahead, u = D_{h/2} y
    step: jax.Array  # steps taken
    failed_at: jax.Array  # the first step whose drift failed (steps + 1: none)


@eqx.filter_jit
def _compiled_run(
    system, bodies, y0, solver, h, steps, distinct, slot_of_save, save_ts, throw
) -> Trajectory:
    """The boundary conversions, the loop and the `Trajectory` (module docstring)."""
    masses = bodies.masses
    term = KeplerInteractionTerm(masses, bodies.gravitational_constant)
    valid = (masses[0] > 0) & jnp.all(masses > 0) & (bodies.gravitational_constant > 0)
    h = eqx.error_if(
        h, ~valid, "WisdomHolman: the masses and G must be positive (masses[0] first)"
    )
    u, ok_start = solver.enter(term, to_jacobi(masses, *y0), h)

    def advance(carry: _Carry, _: Any = None) -> tuple[_Carry, None]:
        u, converged = term.drift(term.kick(carry.u, h), h)
        step = carry.step + 1
        healthy = converged & _finite(u)
        failed_at = jnp.where(
            healthy | (carry.failed_at <= steps), carry.failed_at, step
        )
        return _Carry(u, step, failed_at), None

    def run_steps(carry: _Carry, count: int) -> _Carry:
        return carry if count == 0 else lax.scan(advance, carry, None, count)[0]

    never = jnp.asarray(steps + 1, jnp.int32)
    failed_at = jnp.where(ok_start & _finite(u), never, 0)
    carry = run_steps(_Carry(u, jnp.zeros((), jnp.int32), failed_at), distinct[0])
    first = carry.u
    # Saves at a uniform spacing: nested scans of static lengths (reverse mode
    # works); other spacings: an inner loop of the gap's length (forward mode).
    gaps = np.diff(distinct)
    if gaps.size and np.all(gaps == gaps[0]):

        def uniform_segment(carry: _Carry, _: Any) -> tuple[_Carry, Any]:
            carry = run_steps(carry, int(gaps[0]))
            return carry, carry.u

        carry, later = lax.scan(uniform_segment, carry, None, gaps.size)
    elif gaps.size:

        def uneven_segment(carry: _Carry, gap: jax.Array) -> tuple[_Carry, Any]:
            carry = lax.fori_loop(0, gap, lambda _, c: advance(c)[0], carry)
            return carry, carry.u

        carry, later = lax.scan(uneven_segment, carry, jnp.asarray(gaps, jnp.int32))
    else:
        later = jax.tree_util.tree_map(lambda x: x[None][:0], first)
    per_slot = jax.tree_util.tree_map(
        lambda x, rest: jnp.concatenate([x[None], rest]), first, later
    )

    def synchronised(u_k):
        y_k, converged = solver.leave(term, u_k, h)
        return to_inertial(masses, *y_k), converged

    states, ok_saves = jax.vmap(synchronised)(per_slot)
    order = np.asarray(slot_of_save)
    reached = jnp.asarray(distinct)[order] < carry.failed_at
    good = reached & ok_saves[order]
    q, p = jax.tree_util.tree_map(
        lambda x: jnp.where(good.reshape(-1, 1, 1), x[order], jnp.nan), states
    )
    result = RESULTS.where(
        (carry.failed_at > steps) & jnp.all(ok_saves),
        RESULTS.successful,  # pyright: ignore[reportArgumentType]
        RESULTS.kepler_not_converged,
    )
    if throw:
        q = eqx.error_if(
            q,
            result != RESULTS.successful,
            "WisdomHolman: a Kepler drift did not converge or the state became "
            "non-finite (two bodies met, or a body fell into the star): see "
            "traj.result with throw=False",
        )
    stats = dict(
        num_steps=jnp.asarray(steps),
        num_accepted_steps=jnp.asarray(steps),
        num_rejected_steps=jnp.asarray(0),
        coordinates="Jacobi",
        corrector=0 if solver.corrector is None else solver.corrector,
        failed_at_step=jnp.where(carry.failed_at > steps, -1, carry.failed_at),
    )
    return Trajectory(
        ts=save_ts,
        ys=(q, p),
        system=system,
        args=bodies,
        run_stats=stats,
        result=result,
        solver_name=solver.name,
    )


def _finite(tree: Any) -> jax.Array:
    leaves = jax.tree_util.tree_leaves(tree)
    return jnp.all(jnp.asarray([jnp.all(jnp.isfinite(x)) for x in leaves]))
