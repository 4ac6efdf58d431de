r"""Poincaré surfaces of section for a batch of orbits.

A surface $s(q, p) = 0$ cuts every orbit of an autonomous system; the crossings in a
chosen direction (`direction=+1`: $s$ increasing) form the section. Each orbit is
stepped with a fixed `dt` (a `lax.scan` of one-step `lj.simulate` calls), and a step
over which $s$ changes sign in the wanted direction is remembered by its two end
states, up to `max_crossings` per orbit. After the scan every remembered crossing is
put exactly on the surface by Hénon's trick: from the end nearer the surface, the
equations of motion are integrated with $s$ itself as the independent variable,

$$ \frac{dy}{ds} = \frac{f(y)}{\nabla s\cdot f(y)}, \qquad
   \frac{dt}{ds} = \frac{1}{\nabla s\cdot f(y)}, $$

from $s(y)$ to 0 (classical RK4 in a few substeps over at most half a step, far
below the error of the orbit's own steps), which gives the crossing state and time.

Crossings are returned as arrays of q and p padded with NaN, with the number found.

**References:** Hénon, Physica D 5, 412 (1982) ("On the numerical computation of
Poincaré maps"); Hénon & Heiles, Astron. J. 69, 73 (1964);
Lichtenberg & Lieberman, *Regular and Chaotic Dynamics*, 2nd ed., §1.2b.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax.phase_space.flow import PhaseFlow, interval_count, phase_flow

_HENON_SUBSTEPS = 4
_CHUNK = 64  # steps between two writes of the crossing buffers


class PoincareSection(eqx.Module):
    """The crossings of a batch of orbits with a surface of section.

    - `ts`: crossing times, shape `(batch, max_crossings)`, NaN-padded.
    - `q`, `p`: the coordinates and momenta there, shape `(batch, max_crossings,
      *q_shape)` (p = ∂L/∂q̇ for a Lagrangian), NaN-padded.
    - `count`: crossings found per orbit; above `max_crossings` the later ones were
      not stored (raise `max_crossings` to keep them).
    """

    ts: jax.Array
    q: Any
    p: Any
    count: jax.Array


def _crossed(before: jax.Array, after: jax.Array, direction: int) -> jax.Array:
    upward = (before < 0) & (after >= 0)
    downward = (before > 0) & (after <= 0)
    if direction > 0:
        return upward
    if direction < 0:
        return downward
    return upward | downward


def _scan_for_crossings(flow, level, flat0, steps, dt, direction, max_crossings):
    """The step indices and start states of the first `max_crossings` crossing steps.

    The orbit is stepped in chunks of up to `_CHUNK` steps; the crossings of a chunk
    are written into the buffers by one scatter per chunk (a scatter every step
    would dominate the cost of a batch of orbits), and only the step's start
    state is kept (its end is one step away).
    """

    def step(carry, _):
        y, before = carry
        moved = flow.advance(y, dt)
        after = level(moved)
        hit = _crossed(before, after, direction)
        return (moved, after), (y, hit)

    def chunk(carry, first_index, length):
        y, before, count, indices, starts = carry
        (y, before), (chunk_starts, hits) = jax.lax.scan(
            step, (y, before), None, length=length
        )
        slots = count + jnp.cumsum(hits) - 1
        # Misses and overflow go to slot max_crossings, which the scatter drops.
        slots = jnp.where(hits & (slots < max_crossings), slots, max_crossings)
        step_indices = first_index + jnp.arange(length, dtype=jnp.int32)
        indices = indices.at[slots].set(step_indices, mode="drop")
        starts = starts.at[slots].set(chunk_starts, mode="drop")
        count = count + jnp.sum(hits, dtype=count.dtype)
        return (y, before, count, indices, starts)

    carry = (
        flat0,
        level(flat0),
        jnp.zeros((), dtype=jnp.int32),
        jnp.full(max_crossings, -1, dtype=jnp.int32),
        jnp.zeros((max_crossings, flat0.shape[0]), dtype=flat0.dtype),
    )
    length = min(_CHUNK, steps)
    whole, remainder = divmod(steps, length)

    def full_chunk(carry, first_index):
        return chunk(carry, first_index, length), None

    firsts = length * jnp.arange(whole, dtype=jnp.int32)
    carry, _ = jax.lax.scan(full_chunk, carry, firsts)
    if remainder:
        carry = chunk(carry, jnp.asarray(whole * length, jnp.int32), remainder)
    return carry[2:]


def _henon_step(flow: PhaseFlow, level, y: jax.Array, value: jax.Array):
    r"""(Δt, state) on the surface, from y at surface value `value` (Hénon 1982).

    With the surface value σ = s(y) as the independent variable,
    $dy/d\sigma = f(y)/\dot s$ and $dt/d\sigma = 1/\dot s$ with
    $\dot s = \nabla s \cdot f$; integrating from σ = s(y) to σ = 0 lands exactly
    on the surface. Classical RK4 in `_HENON_SUBSTEPS` substeps over a time span of
    at most half a step keeps its error below that of the orbit's own steps.
    """

    def rate(state):
        y = state[:-1]
        velocity = flow.vector_field(y)
        s_dot = jax.jvp(level, (y,), (velocity,))[1]
        return jnp.append(velocity, 1.0) / s_dot

    def substep(_, state):
        k1 = rate(state)
        k2 = rate(state + 0.5 * h * k1)
        k3 = rate(state + 0.5 * h * k2)
        k4 = rate(state + h * k3)
        return state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    h = -value / _HENON_SUBSTEPS
    start = jnp.append(y, jnp.zeros((), dtype=y.dtype))
    end = jax.lax.fori_loop(0, _HENON_SUBSTEPS, substep, start)
    return end[-1], end[:-1]


def _one_orbit(flow, flat0, surface, steps, dt, direction, max_crossings):
    def level(y):
        return surface(*flow.canonical(y))

    count, indices, starts = _scan_for_crossings(
        flow, level, flat0, steps, dt, direction, max_crossings
    )
    stops = jax.vmap(lambda y: flow.advance(y, dt))(starts)
    ends = jnp.stack([starts, stops], axis=1)
    values = jax.vmap(jax.vmap(level))(ends)
    # Start from the end of the step nearer the surface: Hénon's step is shortest.
    nearer = jnp.argmin(jnp.abs(values), axis=1)
    rows = jnp.arange(max_crossings)
    shifts, states = jax.vmap(lambda y, v: _henon_step(flow, level, y, v))(
        ends[rows, nearer], values[rows, nearer]
    )
    stored = indices >= 0
    ts = jnp.where(stored, (indices + nearer) * dt + shifts, jnp.nan)
    q, p = jax.vmap(flow.canonical)(states)
    blank = jax.tree_util.tree_map(
        lambda x: jnp.where(stored.reshape((-1,) + (1,) * (x.ndim - 1)), x, jnp.nan),
        (q, p),
    )
    return ts, blank[0], blank[1], count


def poincare_section(
    system: Any,
    y0s: tuple[Any, Any],
    t1: float,
    surface: Callable[[Any, Any], jax.Array],
    *,
    direction: int = +1,
    dt: float,
    solver: diffrax.AbstractSolver | None = None,
    args: Any = None,
    max_crossings: int = 256,
    rtol: float = 1e-10,
    atol: float = 1e-10,
) -> PoincareSection:
    """The crossings of `surface(q, p) = 0` by the orbits from `y0s` over [0, t1].

    **Arguments:**
    - `system`: an autonomous `Lagrangian`, Hamiltonian or scene.
    - `y0s`: a batch of initial states, `(q0s, qdot0s)` or `(q0s, p0s)` with a
      leading batch axis on every leaf.
    - `surface`: `s(q, p) -> scalar`; the section is `s = 0` (p = ∂L/∂q̇ for a
      Lagrangian), e.g. `lambda q, p: q[0]` for the plane x = 0.
    - `direction`: +1 crossings with s increasing, −1 decreasing, 0 both.
    - `dt`: the fixed step (t1 a whole multiple of it); `solver` any solver
      `lj.simulate` accepts with a fixed step (default by the system's structure).
    - `max_crossings`: stored crossings per orbit (the array width).

    **Returns:** a `PoincareSection` (`.ts`, `.q`, `.p`, `.count`), NaN-padded.
    """
    if direction not in (-1, 0, 1):
        raise ValueError(f"direction must be +1, -1 or 0 (both); got {direction}")
    if max_crossings < 1:
        raise ValueError(f"max_crossings must be at least 1, got {max_crossings}")
    if dt is None:
        raise ValueError("poincare_section steps with a fixed dt: pass dt.")
    first = jax.tree_util.tree_map(lambda x: jnp.asarray(x)[0], y0s)
    flow, _ = phase_flow(
        system, first, dt=dt, solver=solver, args=args, rtol=rtol, atol=atol
    )
    dt = float(dt)
    steps = interval_count(float(t1), dt, "dt")

    return _section(flow, y0s, surface, steps, dt, direction, max_crossings)


@eqx.filter_jit
def _section(flow, y0s, surface, steps, dt, direction, max_crossings):
    def orbit(y0):
        flat0 = ravel_pytree(y0)[0]
        return _one_orbit(flow, flat0, surface, steps, dt, direction, max_crossings)

    ts, q, p, count = jax.vmap(orbit)(y0s)
    return PoincareSection(ts=ts, q=q, p=p, count=count)
