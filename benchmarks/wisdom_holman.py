r"""Wisdom–Holman splitting on HLW's outer solar system, against Yoshida4 and WHFast.

The Sun (with the inner planets) and the five outer planets of HLW §I.2.4
(`lj.scenes.PlanetarySystem()`), over 10⁶ days (10⁵ with `--quick`), 101 saved
states. Rows, one pinned core:

- `lj.Yoshida4()` at h = 10 days (the issue's reference row: energy 3.8e-9);
- `lj.WisdomHolman()` at h = 10 days, and with the corrector of order 5 at
  h = 10, 50 and 100 days;
- REBOUND's WHFast (if `import rebound` works) at the same steps: without
  corrector in its default safe mode (synchronised every step, as a new user runs
  it), and with corrector 5 in its fast mode (`safe_mode = 0`, synchronised at
  the saves only), the configuration that matches lagjax's loop.

Columns: warm run time (median of five, three with `--quick`; compilation apart),
the largest relative energy error over the saves (energies from the saved
inertial states, one formula for every row), and the ratio of the time to that of
the WHFast row of the same step and corrector. The machine may be loaded: compare
the ratios, measured in one run.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration* (2006),
§I.2.4; Wisdom & Holman, AJ 102, 1528 (1991); Wisdom, Holman & Touma, Fields
Inst. Commun. 10, 217 (1996); Rein & Tamayo, MNRAS 452, 376 (2015).
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Callable

import jax
import numpy as np

import lagjax as lj
from benchmarks.state_timing import timed
from lagjax._integrate.wisdom_holman_run import run_wisdom_holman
from lagjax.scenes.planetary import PlanetarySystem
from lagjax.solvers.wisdom_holman import WisdomHolman

SCENE_STATE = Callable[[], tuple[np.ndarray, np.ndarray]]


def energy(q: np.ndarray, p: np.ndarray, masses: np.ndarray, g: float) -> np.ndarray:
    """H of each saved state (leading axis), in NumPy."""
    kinetic = np.sum(np.sum(p**2, -1) / (2 * masses), -1)
    first, second = np.triu_indices(len(masses), 1)
    distances = np.linalg.norm(q[:, first] - q[:, second], axis=-1)
    return kinetic - g * np.sum(masses[first] * masses[second] / distances, -1)


def lagjax_run(scene: PlanetarySystem, ts: np.ndarray, dt: float, solver) -> Callable:
    y0 = scene.initial_state()

    def run():
        if isinstance(solver, WisdomHolman):
            traj = run_wisdom_holman(scene, y0, 0.0, float(ts[-1]), dt, solver, ts,
                                     None, None, True)  # fmt: skip
        else:
            traj = lj.simulate(scene, y0, t1=float(ts[-1]), dt=dt, ts=ts,
                               solver=solver)  # fmt: skip
        return np.asarray(traj.q), np.asarray(traj.p)

    return run


def whfast_run(
    scene: PlanetarySystem, ts: np.ndarray, dt: float, corrector: int
) -> Callable | None:
    try:
        import rebound
    except ImportError:
        return None
    masses = np.asarray(scene.masses)

    def run():
        sim = rebound.Simulation()
        sim.G = float(scene.gravitational_constant)
        for m, x, v in zip(masses, np.asarray(scene.positions),
                           np.asarray(scene.velocities)):  # fmt: skip
            sim.add(m=float(m), x=x[0], y=x[1], z=x[2], vx=v[0], vy=v[1], vz=v[2])
        sim.integrator = "whfast"
        sim.dt = dt
        sim.integrator.corrector = corrector  # REBOUND 5: fields of sim.integrator
        sim.integrator.safe_mode = 1 if corrector == 0 else 0
        states = np.empty((len(ts), 2, len(masses), 3))
        for index, t in enumerate(ts):
            sim.integrate(float(t), exact_finish_time=0)
            sim.synchronize()
            particles = sim.particles
            states[index, 0] = [(b.x, b.y, b.z) for b in particles]
            states[index, 1] = [(b.vx, b.vy, b.vz) for b in particles]
        return states[:, 0], states[:, 1] * masses[:, None]

    return run


def measured(label, run, scene, repeats) -> dict:
    masses, g = np.asarray(scene.masses), float(scene.gravitational_constant)
    q, p, first, warm = timed(run, repeats)
    energies = energy(q, p, masses, g)
    error = float(np.max(np.abs(energies / energies[0] - 1)))
    return dict(method=label, time_s=warm, first_s=first, energy_error=error)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", help="write the rows here")
    options = parser.parse_args()
    os.sched_setaffinity(0, {max(os.sched_getaffinity(0))})
    lj.enable_fast_cpu_loops()
    jax.config.update("jax_enable_x64", True)
    span = 1e5 if options.quick else 1e6
    repeats = 3 if options.quick else 5
    ts = np.linspace(0.0, span, 101)
    scene = PlanetarySystem()
    runs = [("lagjax Yoshida4 h=10", lagjax_run(scene, ts, 10.0, lj.Yoshida4()), None)]
    runs.append(("lagjax WisdomHolman h=10", lagjax_run(scene, ts, 10.0, WisdomHolman()),
                 "WHFast h=10"))  # fmt: skip
    for dt in (10.0, 50.0, 100.0):
        solver = WisdomHolman(corrector=5)
        runs.append((f"lagjax WisdomHolman corrector=5 h={dt:g}",
                     lagjax_run(scene, ts, dt, solver), f"WHFast corrector=5 h={dt:g}"))  # fmt: skip
    peers = {"WHFast h=10": whfast_run(scene, ts, 10.0, 0)}
    for dt in (10.0, 50.0, 100.0):
        peers[f"WHFast corrector=5 h={dt:g}"] = whfast_run(scene, ts, dt, 5)
    rows = [measured(label, run, scene, repeats) for label, run, _ in runs]
    peer_rows = {
        label: measured(label, run, scene, repeats)
        for label, run in peers.items()
        if run is not None
    }
    for row, (_, _, peer) in zip(rows, runs):
        if peer in peer_rows:
            row["time_vs_whfast"] = row["time_s"] / peer_rows[peer]["time_s"]
    rows += list(peer_rows.values())
    for row in rows:
        ratio = row.get("time_vs_whfast")
        extra = "" if ratio is None else f"  {ratio:.2f}x WHFast"
        print(f"{row['method']:<40} {row['time_s'] * 1e3:8.1f} ms  energy "
              f"{row['energy_error']:.1e}{extra}", flush=True)  # fmt: skip
    if options.json:
        meta = dict(mode="quick" if options.quick else "full", span_days=span)
        with open(options.json, "w") as file:
            json.dump(dict(meta=meta, rows=rows), file, indent=1)


if __name__ == "__main__":
    main()
