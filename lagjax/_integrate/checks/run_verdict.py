r"""A finished run judged after its loop: non-finite states, and divergence of a
fixed-step run whose energy has left any sane bound.

Nothing here is added to the step (a branch per step would split XLA's fused
kernel): the loop only records, and `judge_run` looks at the saved states once,
inside the same compiled call as the loop, and attaches the clear message
(`eqx.error_if`) or, with `throw=False`, reports the failure in `result` and the
stats.

A saved state that is not finite (inf/NaN) fails the run. Saves that diffrax
marks unused (t = inf, as `SaveAt(steps=True)` leaves them) are not results and
are skipped.

A fixed step beyond a method's stability limit (Störmer–Verlet on
$\ddot q = -\omega^2 q$ needs $\omega h < 2$; an explicit Runge–Kutta method on a
stiff problem) does not stop the run: the state grows geometrically and stays
finite for hundreds of steps, and a conservative system reports an energy of
1e20 against 5e3 as if that were a result. For a system that conserves its
energy, the energy error of a stable run with any useful step stays a modest
fraction of the energy scale, so the run is judged after the loop — nothing is
added to the step — by

$$ \max_k |E(t_k) - E_0| \le 10^3 \left(|E_0| + |p_0\cdot\dot q_0|
   + 10^{-4} \max_k |p_k\cdot\dot q_k|\right), $$

over the saved states (the final one at least), where $|p_0\cdot\dot q_0|$ (twice
the kinetic energy for a quadratic one) sets the scale when $E_0 \approx 0$ (it is
left out where p and q̇ are not paired, as for a rigid body's quaternion). The last
term is the motion's own scale for a start at rest where E = 0 (free fall from
y = 0, a pendulum let go at θ = π/2 with V = −cos θ): without it any round-off
counted as divergence (drift 10²⁹³). Its factor keeps a blow-up caught: there
|E − E0| ≈ E ≥ ½ max |p·q̇| (for a quadratic T), a ratio of at least 5·10³ to the
bound's 10³, while a stable run from such a start may err by up to 10 % of its
kinetic energy. It
applies only when the system conserves energy: no generalized forces,
dissipation or constraints (`AbstractSystem.conserves_energy_if_autonomous`), and
$\partial E/\partial t = 0$ at every saved state (autodiff gives exactly zero for
an autonomous system). Elsewhere the drift is NaN and nothing is judged.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
§I.5 (linear stability of Störmer–Verlet), §IX.8 (energy over long times).
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._core.system import AbstractSystem
from lagjax.mechanics.legendre import tree_dot

DIVERGENCE_FACTOR = 1e3
# The share of the largest |p·q̇| along the run in the energy scale (docstring).
MOTION_FRACTION = 1e-4


def energy_drift(
    system: AbstractSystem, state0: Any, t0: Any, saved_ts: Any, ys: Any, args: Any
) -> jax.Array:
    """max |E − E0| / (|E0| + |p0·q̇0| + 10⁻⁴ max |p·q̇|) over the saved states; NaN
    when the system does not conserve energy (module docstring). Saves marked
    t = inf are skipped."""
    if not system.conserves_energy_if_autonomous():
        return jnp.asarray(jnp.nan)
    q0, second0 = state0
    energy0 = system.state_energy(q0, second0, t0, args)
    scale = jnp.abs(energy0) + jnp.abs(_action_rate(system, q0, second0, t0, args))
    scale = jnp.maximum(scale, jnp.finfo(jnp.result_type(scale)).tiny)

    def energy_and_rate(q, second, t):
        energy_of_time = lambda time: system.state_energy(q, second, time, args)
        return jax.value_and_grad(energy_of_time)(t)

    used = jnp.isfinite(saved_ts)
    times = jnp.where(used, saved_ts, t0)
    energies, rates = jax.vmap(energy_and_rate)(ys[0], ys[1], times)
    autonomous = jnp.all(jnp.where(used, rates == 0, True))
    action_rates = jax.vmap(lambda q, s, t: _action_rate(system, q, s, t, args))(
        ys[0], ys[1], times
    )
    motion = jnp.max(jnp.where(used & jnp.isfinite(action_rates),
                               jnp.abs(action_rates), 0.0))  # fmt: skip
    scale = scale + MOTION_FRACTION * motion
    drift = jnp.max(jnp.where(used, jnp.abs(energies - energy0), 0.0)) / scale
    return jnp.where(autonomous, drift, jnp.nan)


def _action_rate(system, q, second, t, args) -> jax.Array:
    """p·q̇ at the state, or 0 where p and q̇ are not paired coordinates (a rigid
    body's momentum has 3 components, its quaternion rate 4)."""
    velocity = system.state_velocity(q, second, t, args)
    momentum = system.state_momentum(q, second, t, args)
    shapes = jax.tree_util.tree_map(jnp.shape, (velocity, momentum))
    if shapes[0] != shapes[1]:
        return jnp.zeros(())
    return tree_dot(momentum, velocity)


def diverged(drift: jax.Array) -> jax.Array:
    """Whether an energy drift (from `energy_drift`) is past the sane bound."""
    return drift > DIVERGENCE_FACTOR


DIVERGENCE_MESSAGE = (
    "The run diverged: the energy of this conservative system changed by more than "
    f"{DIVERGENCE_FACTOR:g} times its scale (|E0| + |p0·q̇0| + 1e-4 max|p·q̇|), so the "
    "saved states are "
    "not a solution. The step is most likely beyond the method's stability limit "
    "(Störmer–Verlet needs ω·dt < 2 for the fastest frequency ω): reduce dt, or use "
    "an implicit or adaptive solver. simulate(..., throw=False) returns the run "
    "instead of raising, with the measured ratio in stats['energy_drift']."
)


NON_FINITE_MESSAGE = (
    "The integration produced a non-finite state (inf/NaN). Likely causes: a "
    "singular mass matrix (degenerate L, or a coordinate singularity such as "
    "Euler-angle gimbal lock), redundant or dependent constraints (a "
    "rank-deficient constraint Jacobian in RATTLE's G M^-1 G^T), a step too large "
    "for a stiff problem, a collision/singular potential, an infinite "
    "parameter in args, or a BitReversible state leaving its integer lattice "
    "(pass q_range= and p_range= above the run's largest |q| and |p|). simulate(..., throw=False) returns the trajectory up to "
    "there instead of raising."
)


def all_saved_states_finite(saved_ts: jax.Array, ys: Any) -> jax.Array:
    """Whether every saved state is finite; slots marked t = inf are skipped."""
    used = jnp.isfinite(saved_ts)

    def leaf_finite(x):
        mask = used.reshape(used.shape + (1,) * (jnp.ndim(x) - used.ndim))
        return jnp.all(jnp.isfinite(x) | ~mask)

    return jnp.all(jnp.stack([leaf_finite(x) for x in jax.tree_util.tree_leaves(ys)]))


def judge_run(
    system: AbstractSystem,
    start: Any,
    t0: Any,
    saved_ts: jax.Array,
    ys: Any,
    args: Any,
    result: Any,
    *,
    fixed_steps: bool,
    throw: bool,
) -> tuple[Any, Any, dict[str, jax.Array]]:
    """`(ys, result, stats)` of a finished run: `stats["finite"]` and
    `stats["succeeded"]` always, and for
    fixed steps `stats["energy_drift"]`, with `result` set to
    `nonlinear_divergence` when the drift is past the bound. With `throw` the
    messages are attached to `ys` (`eqx.error_if`)."""
    finite = all_saved_states_finite(saved_ts, ys)
    finite = finite & (result != diffrax.RESULTS.nonfinite)
    if throw:
        ys = eqx.error_if(ys, ~finite, NON_FINITE_MESSAGE)
    stats = {"finite": finite}
    if fixed_steps:
        # Fixed steps can outrun a method's stability limit with a finite state.
        drift = energy_drift(system, start, t0, saved_ts, ys, args)
        result = diffrax.RESULTS.where(
            diverged(drift) & (result == diffrax.RESULTS.successful),
            diffrax.RESULTS.nonlinear_divergence,  # pyright: ignore[reportArgumentType]
            result,
        )
        if throw:
            ys = eqx.error_if(ys, diverged(drift), DIVERGENCE_MESSAGE)
        stats["energy_drift"] = drift
    # computed in the compiled run, so a concrete caller reads it without an
    # eager comparison of result codes (a compilation of its own)
    stats["succeeded"] = finite & (
        (result == diffrax.RESULTS.successful)
        | (result == diffrax.RESULTS.event_occurred)
    )
    return ys, result, stats
