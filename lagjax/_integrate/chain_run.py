r"""`simulate` with `lj.ChainRegularization`: a chain of closest pairs, re-formed as it goes.

At the boundary the user's $(q, p)$ of shape (N, d) become the chain state
$(\mathbf X, \mathbf W)$ with the chain through the closest pairs, the centre of
mass $\mathbf R_0$ and the total momentum $\mathbf P$
(`lagjax.solvers.chain_coordinates.to_chain`). The loop is that of
`lagjax._integrate.time_transformed_run` — the same stepper (a splitting step,
or an extrapolation step with its refusals) and the same partial steps to the
save times — with one thing added after every step: the chain is built again
from the new separations and, where it changed, the state is carried over to it
(`rechained`) and the solver's state started afresh (its Kahan compensation and
cached force belong to the old vectors). The chain in force at each step is part
of the loop's state, so each save's partial step runs on the masses in that
chain's order. A saved state goes back to body order with the centre of mass at
$\mathbf R_0 + \mathbf P\,(\tau - t_0)/M$.

The loop is a `lax.while_loop` per save time (`jit`, `vmap` over initial states;
not reverse mode); `max_steps` caps the total number of steps, and a run that
stops short marks `traj.result` `max_steps_reached` (an error unless
`throw=False`).

References: Mikkola & Aarseth, Celest. Mech. 57, 439 (1993); Mikkola & Merritt,
AJ 135, 2398 (2008).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from lagjax._core.precision import cast_floats, working_dtype
from lagjax._integrate.time_transformed_run import (
    _partial_step,
    _stepper,
    _time,
    check_fictitious_time_inputs,
)
from lagjax.solvers.chain import CHAIN_HAMILTONIAN, ChainBodies, ChainRegularization
from lagjax.solvers.chain_coordinates import (
    ChainState,
    from_chain,
    rechained,
    to_chain,
)
from lagjax.solvers.time_transformed import extended_state
from lagjax.solvers.wisdom_holman import GravitatingBodies
from lagjax.trajectory import Trajectory

# The system's H at the start must match the bodies' Newtonian energy this closely
# (relative to |T| + |V|): the chain integrates pairwise gravity, not the system's H.
NEWTONIAN_MATCH = 1e-9


def run_chain(
    system: Any, y0: Any, t0: Any, t1: Any, ds: Any, solver: ChainRegularization,
    ts: Any, args: Any, max_steps: int | None, throw: bool,
    tolerances: dict[str, Any], **options: Any,
) -> Trajectory:  # fmt: skip
    """`simulate` for a `ChainRegularization` solver: the checks, the run, the
    verdict. `tolerances`: simulate's rtol/atol as given (refused: an
    extrapolating solver carries its own)."""
    named = [name for name, value in tolerances.items() if value is not None]
    if named:
        raise ValueError(
            f"{solver.name} takes no {' or '.join(named)} from simulate: pass "
            "them to its solver, e.g. lj.ChainRegularization(lj.GraggBulirschStoer("
            "rtol=3e-14, atol=3e-14))"
        )
    y0, t1 = check_fictitious_time_inputs(
        solver.name, "the first fictitious step ds",
        system, y0, t0, t1, ds, ts, args, max_steps, options,
    )  # fmt: skip
    system, args = system.resolve(args)
    if not isinstance(args, GravitatingBodies):
        raise TypeError(
            f"{solver.name} integrates gravitating bodies: pass a system whose args "
            "carry masses and gravitational_constant (the Pythagorean scene, a "
            f"PlanetarySystem); got args of type {type(args).__name__}"
        )
    dtype = working_dtype(y0)
    y0, args = cast_floats(y0, dtype), cast_floats(args, dtype)
    check_bodies(solver.name, args, y0)
    _check_newtonian(solver.name, system, args, y0, t0)
    save_ts = jnp.reshape(jnp.asarray(t1 if ts is None else ts, dtype=dtype), (-1,))
    trajectory = _compiled_run(
        system, args, y0, solver, jnp.asarray(t0, dtype), jnp.asarray(ds, dtype),
        save_ts, max_steps,
    )  # fmt: skip
    if throw:
        trajectory = eqx.error_if(
            trajectory,
            trajectory.result != diffrax.RESULTS.successful,
            f"{solver.name} did not reach the last save time (raise max_steps), or "
            "the masses or G were not positive",
        )
    return trajectory


def check_bodies(name: str, bodies: Any, y0: Any) -> None:
    """At least two bodies, one row of q0 and p0 per mass, positive masses and G
    (traced values are checked in the compiled run)."""
    masses = bodies.masses
    if jnp.ndim(masses) != 1 or jnp.shape(masses)[0] < 2:
        raise ValueError(
            f"{name} needs masses of shape (N,) with N ≥ 2 bodies (a chain links "
            f"pairs); got shape {jnp.shape(masses)}"
        )
    count = jnp.shape(masses)[0]
    for part, label in zip(y0, ("positions q0", "momenta p0")):
        if jnp.ndim(part) != 2 or jnp.shape(part)[0] != count:
            raise ValueError(
                f"{name}: {label} must have shape (N, d) with N = {count}, one row "
                f"per mass; got {jnp.shape(part)}"
            )
    if not isinstance(masses, Tracer) and not np.all(np.asarray(masses) > 0):
        raise ValueError(
            f"{name}: every mass must be positive; got masses = {np.asarray(masses)}"
        )
    gravity = bodies.gravitational_constant
    if not isinstance(gravity, Tracer) and not float(gravity) > 0:
        raise ValueError(
            f"{name}: the gravitational constant must be positive; got {float(gravity)}"
        )


@eqx.filter_jit
def _start_energies(system: Any, bodies: Any, q: Any, p: Any, t0: Any):
    """(the system's H, T and V of the point masses under pairwise Newtonian
    gravity) at the start. Compiled: evaluated op by op it took 45 ms, three times
    the run it checks."""
    masses = bodies.masses
    kinetic = 0.5 * jnp.sum(p**2 / masses[:, None])
    distance = jnp.sqrt(jnp.sum((q[:, None] - q[None, :]) ** 2, axis=-1))
    upper = np.triu(np.ones((masses.shape[0],) * 2, dtype=bool), 1)
    strengths = masses[:, None] * masses[None, :] / jnp.where(upper, distance, 1.0)
    potential = -bodies.gravitational_constant * jnp.sum(jnp.where(upper, strengths, 0))
    return system.state_energy(q, p, t0, bodies), kinetic, potential


def _check_newtonian(name: str, system: Any, bodies: Any, y0: Any, t0: Any) -> None:
    """The system's H at the start must be the bodies' Newtonian energy with p the
    momenta: the chain integrates pairwise gravity, whatever H the system has."""
    if not system.second_is_momentum:
        raise ValueError(
            f"{name} needs the state (q, p) with p the momenta; this system's second "
            "component is q̇"
        )
    q0, p0 = y0
    values = _start_energies(system, bodies, q0, p0, t0)
    if any(isinstance(value, Tracer) for value in values):
        return
    energy, kinetic, potential = (float(value) for value in values)
    scale = abs(kinetic) + abs(potential)
    if not abs(energy - (kinetic + potential)) <= NEWTONIAN_MATCH * scale:
        raise ValueError(
            f"{name} integrates point masses under pairwise Newtonian gravity, but "
            f"this system's H at the start is {energy:.16g}, not their energy "
            f"{kinetic + potential:.16g} (T + V with T = Σ|p|²/2m)"
        )


class _Walk(NamedTuple):
    """The `while_loop`'s state: the extended chain state ((W, p_t), (X, t)), the
    solver's state, the fictitious step, the chain's order, the step, refusal and
    re-chaining counts, and the last step's start (state, step, order)."""

    y: Any
    solver_state: Any
    ds: jax.Array
    order: jax.Array
    steps: jax.Array
    rejected: jax.Array
    rechains: jax.Array
    start: Any


def _chain_stepper(solver: ChainRegularization, terms: Any, flow_args: Any):
    """`one_step(walk) -> walk`: a step of the time-transformed method on the
    chain, then the chain re-formed (module docstring)."""
    splitting = solver.splitting

    def one_step(walk: _Walk) -> _Walk:
        advance = _stepper(terms, splitting, flow_args(walk.order))
        y1, solver_state, ds_next, accepted = advance(
            walk.y, walk.solver_state, walk.ds
        )
        (W, p_t), (X, t) = y1
        chain, changed = rechained(ChainState(X, W, walk.order))
        y1 = ((chain.W, p_t), (chain.X, t))

        def fresh_state():
            zero = jnp.zeros_like(t)
            return splitting.init(terms, zero, ds_next, y1, flow_args(chain.order))

        solver_state = lax.cond(changed, fresh_state, lambda: solver_state)
        refused = 1 - jnp.asarray(accepted, jnp.int32)
        return _Walk(y1, solver_state, ds_next, chain.order, walk.steps + 1,
                     walk.rejected + refused, walk.rechains + changed.astype(jnp.int32),
                     (walk.y, walk.ds, walk.order))  # fmt: skip

    return one_step


@eqx.filter_jit
def _compiled_run(system, bodies, y0, solver, t0, ds, save_ts, max_steps):
    """The chain at the start, the loop to each save time, the partial steps, and
    the states back in body order."""
    masses, gravity = bodies.masses, bodies.gravitational_constant
    valid = jnp.all(masses > 0) & (gravity > 0)

    def flow_args(order: jax.Array) -> ChainBodies:
        return ChainBodies(masses[order], gravity)

    chain, centre, momentum = to_chain(masses, *y0)
    terms = solver.terms()
    y_start = extended_state(CHAIN_HAMILTONIAN, (chain.X, chain.W), t0,
                             flow_args(chain.order))  # fmt: skip
    # extended_state gives ((p, p_t), (q, t)) for y0 = (q, p): here (X, W).
    state0 = solver.splitting.init(terms, jnp.zeros_like(t0), ds, y_start,
                                   flow_args(chain.order))  # fmt: skip
    one_step = _chain_stepper(solver, terms, flow_args)
    limit = jnp.iinfo(jnp.int32).max if max_steps is None else max_steps

    def to_save(walk: _Walk, tau: jax.Array) -> tuple[_Walk, Any]:
        walk = lax.while_loop(
            lambda w: (_time(w.y) < tau) & (w.steps < limit) & valid, one_step, walk
        )
        return walk, (*walk.start, _time(walk.y) >= tau)

    count = jnp.zeros((), jnp.int32)
    walk = _Walk(y_start, state0, ds, chain.order, count, count, count,
                 (y_start, ds, chain.order))  # fmt: skip
    end, starts = lax.scan(to_save, walk, save_ts)
    q, p, t_landed = _states_at_saves(
        solver, terms, flow_args, starts, save_ts, (masses, centre, momentum, t0)
    )
    reached = (_time(end.y) >= save_ts[-1]) & valid
    result = diffrax.RESULTS.where(
        reached, diffrax.RESULTS.successful, diffrax.RESULTS.max_steps_reached
    )
    stats = dict(
        num_steps=end.steps,
        num_accepted_steps=end.steps - end.rejected,
        num_rejected_steps=end.rejected,
        num_rechains=end.rechains,
        time_residual=jnp.nanmax(jnp.abs(t_landed - save_ts)),
        energy_start=-y_start[0][1] + jnp.sum(momentum**2) / (2 * jnp.sum(masses)),
    )
    return Trajectory(ts=save_ts, ys=(q, p), system=system, args=bodies,
                      run_stats=stats, result=result, solver_name=solver.name)  # fmt: skip


def _states_at_saves(solver, terms, flow_args, starts, save_ts, bodies):
    """(q, p, t) at the save times in body order: from each recorded step start
    a partial step that ends at the save time (`_partial_step`), taken back from
    the chain in force at that step; NaN where the run stopped short of it."""
    y, ds, orders, reached = starts
    masses, centre, momentum, t0 = bodies
    splitting = solver.splitting

    def landed_at(y, tau, ds, order):
        def one_step(y, h):  # a step of fictitious length h in this chain
            zero = jnp.zeros((), h.dtype)
            state = splitting.init(terms, zero, h, y, flow_args(order))
            return splitting.step(terms, zero, h, y, flow_args(order), state, False)[0]

        return _partial_step(one_step, y, tau, ds)

    landed = jax.vmap(landed_at)(y, save_ts, ds, orders)
    (W, _), (X, t_landed) = landed
    centres = centre + (save_ts - t0)[:, None] * momentum / jnp.sum(masses)
    q, p = jax.vmap(
        lambda X, W, order, centre: from_chain(
            masses, ChainState(X, W, order), centre, momentum
        )
    )(X, W, orders, centres)
    unreached = ~reached[:, None, None]
    q, p = (jnp.where(unreached, jnp.nan, x) for x in (q, p))
    return q, p, jnp.where(reached, t_landed, jnp.nan)
