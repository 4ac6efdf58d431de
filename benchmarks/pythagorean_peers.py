"""The Pythagorean three-body problem by other hands, for `close_encounters` and
`pythagorean_chain`: a hand-written JAX twin of `TimeTransformed(Yoshida4())`,
REBOUND's IAS15, and heyoka's Taylor integrator (each None where the peer is not
installed). Each returns a call that runs the problem from its start and gives
(q, p) at the save times (the twin: at the end).

References: Szebehely & Peters, AJ 72, 876 (1967); Rein & Spiegel, MNRAS 446,
1424 (2015) (IAS15); Biscani & Izzo, MNRAS 504, 2614 (2021) (heyoka); Mikkola &
Tanikawa, Celest. Mech. 74, 287 (1999) (the logarithmic leapfrog).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.lax as lax
import jax.numpy as jnp
import numpy as np

from lagjax.solvers.splitting_tables import YOSHIDA4_WEIGHTS


def twin_run(scene, t1: float, ds: float) -> Callable:
    """A hand-written JAX twin of `TimeTransformed(Yoshida4())` on the three bodies:
    the drift-first logarithmic leapfrog composed by Yoshida's weights, the
    increments added to the state with Kahan's sum, a `while_loop` to t1 (no saves):
    the library's step without its generality."""
    masses = np.asarray(scene.masses)
    pairs = [(i, j) for i in range(3) for j in range(i + 1, 3)]

    def binding_and_gradient(q):  # U = −V and ∂V/∂q, pair by pair
        binding, gradient = 0.0, [jnp.zeros(2) for _ in range(3)]
        for i, j in pairs:
            d = q[i] - q[j]
            inverse = 1 / jnp.sqrt(d @ d)
            binding = binding + masses[i] * masses[j] * inverse
            pull = masses[i] * masses[j] * inverse**3 * d
            gradient[i], gradient[j] = gradient[i] + pull, gradient[j] - pull
        return binding, jnp.stack(gradient)

    def kahan(x, increment, compensation):
        corrected = increment - compensation
        total = x + corrected
        return total, (total - x) - corrected

    def step(state):
        q, t, p, p_t, compensation = state
        stage_q, stage_t, stage_p = q, t, p
        for weight in YOSHIDA4_WEIGHTS:
            for half in (0, 1):
                kinetic = 0.5 * jnp.sum(stage_p**2 / masses[:, None])
                rate = 0.5 * weight * ds / (kinetic + p_t)
                stage_q = stage_q + rate * stage_p / masses[:, None]
                stage_t = stage_t + rate
                if half == 0:
                    binding, gradient = binding_and_gradient(stage_q)
                    stage_p = stage_p - weight * ds / binding * gradient
        new = (stage_q, stage_t, stage_p)
        summed = [kahan(x, n - x, c) for x, n, c in zip((q, t, p), new, compensation)]
        (q, cq), (t, ct), (p, cp) = summed
        return q, t, p, p_t, (cq, ct, cp)

    @jax.jit
    def run_to_end(q0):
        binding, _ = binding_and_gradient(q0)
        # At rest: p_t = −E = U(q0).
        state = (q0, 0.0 * binding, jnp.zeros_like(q0), binding,
                 (jnp.zeros_like(q0), 0.0 * binding, jnp.zeros_like(q0)))  # fmt: skip
        done = lax.while_loop(lambda c: c[0][1] < t1, lambda c: (step(c[0]), c[1] + 1),
                              (state, 0))  # fmt: skip
        return done[0][0], done[0][2], done[1]

    q0 = scene.initial_state()[0]

    def run():
        q, p, run.steps = jax.block_until_ready(run_to_end(q0))  # pyright: ignore
        return np.asarray(q)[None], np.asarray(p)[None]

    return run


def rebound_run(scene, ts: np.ndarray) -> Callable | None:
    try:
        import rebound
    except ImportError:
        return None
    masses = np.asarray(scene.masses)
    q0 = np.asarray(scene.initial_state()[0])

    def run():
        simulation = rebound.Simulation()
        simulation.G = float(scene.gravitational_constant)
        simulation.integrator = "ias15"
        for mass, (x, y) in zip(masses, q0):
            simulation.add(m=float(mass), x=float(x), y=float(y))
        q, p = np.empty((len(ts), 3, 2)), np.empty((len(ts), 3, 2))
        for k, t in enumerate(ts):
            simulation.integrate(float(t), exact_finish_time=1)
            for i, particle in enumerate(simulation.particles):
                q[k, i] = particle.x, particle.y
                p[k, i] = masses[i] * particle.vx, masses[i] * particle.vy
        return q, p

    return run


def heyoka_run(scene, ts: np.ndarray) -> Callable | None:
    try:
        import heyoka as hy
    except ImportError:
        return None
    masses = [float(m) for m in np.asarray(scene.masses)]
    gravity = float(scene.gravitational_constant)
    names = [f"{axis}{i}" for i in range(3) for axis in ("x", "y", "vx", "vy")]
    variables = hy.make_vars(*names)
    x, y = variables[0::4], variables[1::4]
    vx, vy = variables[2::4], variables[3::4]
    system = []
    for i in range(3):
        ax = ay = 0.0
        for j in range(3):
            if j != i:
                r3 = ((x[j] - x[i]) ** 2 + (y[j] - y[i]) ** 2) ** 1.5
                ax = ax + gravity * masses[j] * (x[j] - x[i]) / r3
                ay = ay + gravity * masses[j] * (y[j] - y[i]) / r3
        system += [(x[i], vx[i]), (y[i], vy[i]), (vx[i], ax), (vy[i], ay)]
    q0 = np.asarray(scene.initial_state()[0])
    start = np.zeros(12)
    start[0::4], start[1::4] = q0[:, 0], q0[:, 1]
    integrator = hy.taylor_adaptive(system, start, tol=1e-16)
    column = np.asarray(masses)[:, None]

    def run():
        integrator.time = 0.0
        integrator.state[:] = start
        states = integrator.propagate_grid(ts)[-1].reshape(len(ts), 3, 4)
        return states[..., :2], column * states[..., 2:]

    return run
