r"""A hand-written JAX twin of `TimeTransformed(GraggBulirschStoer)` on three bodies.

The library's extrapolated logarithmic leapfrog (`lagjax.solvers.extrapolation`)
without its generality: the force and the energies written out pair by pair on
the coordinates' scalars, the k leapfrog runs side by side as arrays of length k,
the same tables, the same Aitken–Neville tableau on the increments, the same error
norm (the RMS over the extended state's 14 components, p_t's error being zero),
the same step control and Kahan sum of the state, in a `while_loop` to t1 with no
saves. `benchmarks/close_encounters.py --extrapolation` times it (`gbs_twin_run`)
against the library's run, eager and inside `jax.jit` (`jitted_lagjax_run`), for the
time per step.

References: Mikkola & Aarseth, Celest. Mech. 84, 343 (2002); Hairer, Nørsett &
Wanner, *Solving ODEs I* (1993), §II.9.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.lax as lax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from lagjax.solvers.extrapolation import (
    GROWTH_LIMIT,
    SAFETY,
    SHRINK_LIMIT,
    _substep_tables,
)

# The extended state's components: p (6), p_t, q (6), t.
COMPONENTS = 14


def gbs_twin(
    masses: np.ndarray, t1: float, substeps: tuple[int, ...], tol: float, ds0: float
) -> Callable:
    """`run(q0) -> (p, q, steps, rejected)` for bodies at rest at q0 (3, 2)."""
    m = [float(x) for x in masses]
    pairs = [(i, j) for i in range(3) for j in range(i + 1, 3)]
    counts = np.asarray(substeps, float)
    a_weights, b_weights = _substep_tables(substeps)
    columns = len(substeps)

    def binding_and_gradient(q):  # U = −V and ∂V/∂q on 6 coordinates
        binding, gradient = 0.0, [0.0] * 6
        for i, j in pairs:
            dx, dy = q[2 * i] - q[2 * j], q[2 * i + 1] - q[2 * j + 1]
            inverse = 1 / jnp.sqrt(dx * dx + dy * dy)
            binding = binding + m[i] * m[j] * inverse
            pull = m[i] * m[j] * inverse**3
            gradient[2 * i] += pull * dx
            gradient[2 * i + 1] += pull * dy
            gradient[2 * j] -= pull * dx
            gradient[2 * j + 1] -= pull * dy
        return binding, gradient

    def increments(p, p_t, q, ds):
        """The k runs' increments of (p, q, t), lanes last."""
        h = ds / jnp.asarray(counts)
        dp, dq, dt = [jnp.zeros(columns)] * 6, [jnp.zeros(columns)] * 6, 0.0

        def drift(factor, dp, dq, dt):
            stage_p = [p[c] + dp[c] for c in range(6)]
            kinetic = sum(
                (stage_p[2 * i] ** 2 + stage_p[2 * i + 1] ** 2) / (2 * m[i])
                for i in range(3)
            )
            rate = factor / (kinetic + p_t)
            dq = [dq[c] + rate * stage_p[c] / m[c // 2] for c in range(6)]
            return dq, dt + rate

        def kick(factor, dp, dq):
            binding, gradient = binding_and_gradient([q[c] + dq[c] for c in range(6)])
            return [dp[c] - factor / binding * gradient[c] for c in range(6)]

        dq, dt = drift(0.5 * h, dp, dq, dt)
        for sweep in range(max(substeps)):
            dp = kick(a_weights[sweep] * h, dp, dq)
            dq, dt = drift(b_weights[sweep] * h, dp, dq, dt)
        return jnp.stack([*dp, *dq, dt])

    def extrapolate(runs):
        column, previous = runs, runs
        for level in range(1, columns):
            ratios = (counts[level:] / counts[: columns - level]) ** 2 - 1
            previous = column
            column = column[:, 1:] + (column[:, 1:] - column[:, :-1]) / ratios
        return column[:, -1], previous[:, -1]

    def step(carry):
        y, p_t, compensation, ds, steps, rejected = carry
        best, second = extrapolate(increments(y[:6], p_t, y[6:12], ds))
        corrected = best + compensation
        y1 = y + corrected
        scale = tol + tol * jnp.maximum(jnp.abs(y), jnp.abs(y1))
        ratio = jnp.sqrt(jnp.sum(((best - second) / scale) ** 2) / COMPONENTS)
        accepted = ratio <= 1
        factor = SAFETY * jnp.where(ratio > 0, ratio, 1e-10) ** (-1 / (2 * columns - 1))
        factor = jnp.clip(factor, SHRINK_LIMIT, GROWTH_LIMIT)
        return (
            jnp.where(accepted, y1, y),
            p_t,
            jnp.where(accepted, corrected - (y1 - y), compensation),
            ds * factor,
            steps + 1,
            rejected + 1 - accepted.astype(jnp.int32),
        )

    @jax.jit
    def run(q0):
        q0 = jnp.reshape(q0, -1)
        binding, _ = binding_and_gradient(q0)
        # At rest: p_t = −E = U(q0); the state (p, q, t) as one vector.
        y = jnp.concatenate([jnp.zeros(6), q0, jnp.zeros(1)])
        carry = (y, binding, jnp.zeros(13), jnp.asarray(ds0), 0, 0)
        y, _, _, _, steps, rejected = lax.while_loop(
            lambda c: c[0][12] < t1, step, carry
        )
        return y[:6].reshape(3, 2), y[6:12].reshape(3, 2), steps, rejected

    return run


def jitted_lagjax_run(scene, ts: np.ndarray, solver, ds: float) -> Callable:
    """`lagjax_run` inside `jax.jit`: the checks and set-up traced once, so a call
    is the compiled loop alone (an eager `simulate` call adds a few ms of checks)."""
    y0 = scene.initial_state()

    @jax.jit
    def go(y0):
        traj = lj.simulate(scene, y0, t1=float(ts[-1]), ts=ts, solver=solver, dt=ds)
        return traj.q, traj.p, traj.stats["num_steps"], traj.stats["num_rejected_steps"]

    def run():
        q, p, steps, rejected = jax.block_until_ready(go(y0))
        run.steps, run.rejected = int(steps), int(rejected)  # pyright: ignore
        return np.asarray(q), np.asarray(p)

    return run


def gbs_twin_run(scene, t1: float, substeps: tuple[int, ...], tol: float) -> Callable:
    """The hand-written twin of `TimeTransformed(GraggBulirschStoer)` (no saves;
    `benchmarks.extrapolation_twin`), its final state in the place of t = 70's."""
    twin = gbs_twin(np.asarray(scene.masses), t1, substeps, tol, ds0=0.1)
    q0 = scene.initial_state()[0]

    def run():
        p, q, steps, rejected = jax.block_until_ready(twin(q0))
        run.steps, run.rejected = int(steps), int(rejected)  # pyright: ignore
        return np.asarray(q)[None], np.asarray(p)[None]

    return run
