"""Cost of the N-body force derived by autodiff, against a hand-written one.

100 bodies under softened gravity, F_i = Σ_j G m_i m_j (r_j − r_i)/(|r_j − r_i|² + ε²)^{3/2}.
The force is

(a) hand-written and vectorized: all N × N separations by broadcasting, no Python
    loop and no autodiff;
(b) lagjax: `newtonian_gravity(masses, ...).potential_force`, i.e. −∇V by autodiff of
    the dense, masked pair sum in `lagjax.mechanics.particles`;
(c) autodiff of the same V written on an index list of the N(N−1)/2 pairs (gather,
    so its gradient is a scatter-add) — a design `particles.py` did not take;
(d) plain autodiff of the dense masked sum, without the custom derivative rule
    that `particles.py` adds.

Each is timed as one jit-compiled evaluation and inside a hand-written Störmer–Verlet
`lax.scan` of `--steps` steps; `lj.simulate(..., solver=lj.StormerVerlet())` on the
same system is timed too. Run time is the median of `--repeats` runs after a warm-up
(compile excluded, `block_until_ready`). Ratios are against (a).

Run: `python -m benchmarks.particles [--bodies N] [--steps S] [--repeats R]`.
"""

from __future__ import annotations

import argparse
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import lagjax as lj  # noqa: E402
from lagjax.mechanics.particles import newtonian_gravity  # noqa: E402

SOFTENING = 0.05
DT = 1e-3


def handwritten_force(masses):
    """Vectorized closed form; the diagonal (i = j) contributes a zero separation."""
    coupling = masses[:, None] * masses[None, :]

    def force(positions):
        separation = positions[None, :, :] - positions[:, None, :]  # r_j − r_i
        squared = jnp.sum(separation**2, axis=-1) + SOFTENING**2
        inverse_cube = coupling / (squared * jnp.sqrt(squared))
        return jnp.einsum("ij,ijk->ik", inverse_cube, separation)

    return force


def pair_list_force(masses):
    """−∇V with V summed over an index list of pairs (gather / scatter-add)."""
    first, second = (jnp.asarray(x) for x in np.triu_indices(masses.shape[0], k=1))
    coupling = masses[first] * masses[second]

    def potential(positions):
        separation = positions[first] - positions[second]
        distance_sq = jnp.sum(separation**2, axis=-1) + SOFTENING**2
        return -jnp.sum(coupling / jnp.sqrt(distance_sq))

    return lambda positions: -jax.grad(potential)(positions)


def plain_masked_force(masses):
    """−∇V by plain autodiff of the dense masked sum: lagjax's layout without its
    custom derivative rule."""
    coupling = masses[:, None] * masses[None, :]
    upper = np.triu(np.ones((masses.shape[0],) * 2, dtype=bool), k=1)

    def potential(positions):
        separation = positions[:, None, :] - positions[None, :, :]
        squared = jnp.where(upper, jnp.sum(separation**2, axis=-1), 1.0)
        energies = coupling / jnp.sqrt(squared + SOFTENING**2)
        return -jnp.sum(jnp.where(upper, energies, 0.0))

    return lambda positions: -jax.grad(potential)(positions)


def verlet_loop(force, masses, steps):
    """Kick–drift–kick, the end-of-step force reused at the next start: one force
    evaluation per step, as lagjax's splitting solvers do."""
    inverse_mass = 1.0 / masses[:, None]

    def step(state, _):
        q, p, f = state
        p = p + 0.5 * DT * f
        q = q + DT * inverse_mass * p
        f = force(q)
        p = p + 0.5 * DT * f
        return (q, p, f), None

    def run(q, p):
        return jax.lax.scan(step, (q, p, force(q)), None, length=steps)[0][:2]

    return run


def compile_all(candidates):
    """{name: (compiled, inputs, compile seconds)} for {name: (fn, inputs)}."""
    compiled = {}
    for name, (fn, inputs) in candidates.items():
        start = time.perf_counter()
        call = jax.jit(fn).lower(*inputs).compile()
        compiled[name] = (call, inputs, time.perf_counter() - start)
        jax.block_until_ready(call(*inputs))  # warm-up
    return compiled


def interleaved_runs(compiled, repeats, calls):
    """{name: [seconds per call, ...]}: each sample is `calls` back-to-back calls,
    and the candidates take turns so that a busy spell on the shared machine slows
    all of them alike (ratios are taken per round). Back-to-back calls, because a
    single ~0.1 ms call measured faster when it came first in its round."""
    runs = {name: [] for name in compiled}
    for _ in range(repeats):
        for name, (call, inputs, _) in compiled.items():
            start = time.perf_counter()
            for _ in range(calls):
                output = call(*inputs)
            jax.block_until_ready(output)
            runs[name].append((time.perf_counter() - start) / calls)
    return runs


def report(title, candidates, repeats, unit, calls=1):
    compiled = compile_all(candidates)
    runs = interleaved_runs(compiled, repeats, calls)
    baseline = runs[next(iter(runs))]
    scale = {"µs": 1e6, "ms": 1e3}[unit]
    print(f"\n{title}")
    print(f"{'':36s} {'compile s':>9s} {'median run':>12s} {'ratio':>6s}")
    for name, seconds in runs.items():
        ratio = statistics.median(a / b for a, b in zip(seconds, baseline))
        print(
            f"{name:36s} {compiled[name][2]:9.2f} "
            f"{scale * statistics.median(seconds):9.1f} {unit} {ratio:6.2f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--bodies", type=int, default=100)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=15)
    options = parser.parse_args()

    rng = np.random.default_rng(0)
    masses = jnp.asarray(rng.uniform(0.5, 1.5, options.bodies))
    q0 = jnp.asarray(rng.normal(size=(options.bodies, 3)))
    p0 = masses[:, None] * jnp.asarray(0.3 * rng.normal(size=(options.bodies, 3)))
    system = newtonian_gravity(masses, softening=SOFTENING)
    forces = {
        "(a) hand-written, vectorized": handwritten_force(masses),
        "(b) lagjax −∇V, dense masked": system.potential_force,
        "(c) −∇V, pair index list": pair_list_force(masses),
        "(d) −∇V, dense masked, no rule": plain_masked_force(masses),
    }
    reference = forces["(a) hand-written, vectorized"](q0)
    print(f"{options.bodies} bodies, softened gravity, float64")
    for name, force in forces.items():
        difference = float(jnp.max(jnp.abs(force(q0) - reference)))
        print(f"{name:36s} max |F − F_hand| = {difference:.1e}")
    report(
        "one force evaluation",
        {name: (force, (q0,)) for name, force in forces.items()},
        options.repeats,
        "µs",
        calls=200,
    )
    t1 = options.steps * DT
    loops = {
        name: (verlet_loop(force, masses, options.steps), (q0, p0))
        for name, force in forces.items()
    }
    loops["(b) in lj.simulate(StormerVerlet)"] = (
        lambda q, p: (
            lj.simulate(system, (q, p), t1=t1, dt=DT, solver=lj.StormerVerlet()).q
        ),
        (q0, p0),
    )
    report(f"{options.steps} Störmer–Verlet steps", loops, options.repeats, "ms")


if __name__ == "__main__":
    main()
