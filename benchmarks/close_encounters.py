r"""Close encounters: the Pythagorean three-body problem to t = 70, against IAS15 and heyoka.

Burrau's problem (`lagjax.scenes.pythagorean`, masses 3, 4, 5 at rest on a 3-4-5
triangle, G = 1) saved at t = 0, 1, …, 70. Rows, one pinned core:

- `lj.TimeTransformed(...)` (the logarithmic Hamiltonian, dt/ds = 1/Σ Gmᵢmⱼ/rᵢⱼ)
  with Yoshida4, BlanesMoan4 and Yoshida6 at fictitious steps ds;
- `lj.Taylor` at rtol = atol = 1e-15, JAX route and heyoka route;
- `diffrax.Dopri8` at rtol = atol = 1e-15 through `lj.simulate`;
- peers, where importable: REBOUND's IAS15 (`rebound>=4`, the `bench` extra) and
  heyoka's Taylor method on hand-written equations (tol 1e-16).

Columns: warm run time (median of three; compilation apart), the largest relative
energy error over the saves and at t = 70, the largest |total momentum| and
|angular momentum| (zero at the start), the position difference at t = 30 from
IAS15 (the chaotic run's state after the first encounters), and the escape: the
lightest body's energy relative to the binary at t = 70 (positive: it escapes) and
whether its distance from the binary grows over the last ten time units.
`--quick` runs to t = 30 only (before the escape), two ds per table, no JAX-route
Taylor row.

References: Szebehely & Peters, AJ 72, 876 (1967); Mikkola & Tanikawa, Celest.
Mech. 74, 287 (1999); Rein & Spiegel, MNRAS 446, 1424 (2015) (IAS15); Biscani &
Izzo, MNRAS 504, 2614 (2021) (heyoka).
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Callable

import diffrax
import jax
import numpy as np

import lagjax as lj
from benchmarks.state_timing import timed
from lagjax.scenes.pythagorean import PythagoreanThreeBody

COMPARE_AT = 30


def measures(scene: PythagoreanThreeBody, q: np.ndarray, p: np.ndarray) -> dict:
    """Energy, momenta and escape of a run saved at t = 0, 1, …"""
    masses = np.asarray(scene.masses)
    kinetic = 0.5 * np.sum(p**2 / masses[:, None], axis=(-1, -2))
    energy = kinetic + np.asarray(jax.vmap(lambda x: scene.system().potential_energy(
        x, 0.0, scene))(q))  # fmt: skip
    relative = np.abs(energy / float(scene.energy()) - 1)
    angular = q[..., 0] * p[..., 1] - q[..., 1] * p[..., 0]
    separation, _ = scene.relative_motion(q, p)
    distance = np.linalg.norm(np.asarray(separation), axis=-1)
    return dict(
        energy=float(np.max(relative)),
        energy_end=float(relative[-1]),
        momentum=float(np.max(np.abs(p.sum(-2)))),
        angular_momentum=float(np.max(np.abs(angular.sum(-1)))),
        escape_energy=float(scene.escape_energy(q[-1], p[-1])),
        receding=bool(np.all(np.diff(distance[-10:]) > 0)),
    )


def lagjax_run(scene, ts: np.ndarray, solver, **options) -> Callable:
    y0 = scene.initial_state()

    def run():
        traj = lj.simulate(scene, y0, t1=float(ts[-1]), ts=ts, solver=solver,
                           **options)  # fmt: skip
        return np.asarray(traj.q), np.asarray(traj.p)

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


def runs(scene, ts: np.ndarray, quick: bool) -> dict[str, Callable | None]:
    steps = (0.02, 0.01) if quick else (0.02, 0.01, 0.005)
    tables = dict(
        Yoshida4=lj.Yoshida4, BlanesMoan4=lj.BlanesMoan4, Yoshida6=lj.Yoshida6
    )
    rows: dict[str, Callable | None] = {
        f"TimeTransformed({name}) ds={ds}": lagjax_run(
            scene, ts, lj.TimeTransformed(table()), dt=ds
        )
        for name, table in tables.items()
        for ds in steps
    }
    # The JAX route takes seconds here (3,548 steps of order 20 to t = 70): full only.
    for backend in ("heyoka",) if quick else ("jax", "heyoka"):
        rows[f"Taylor({backend}) 1e-15"] = lagjax_run(
            scene, ts, lj.Taylor(rtol=1e-15, atol=1e-15, backend=backend)
        )
    rows["Dopri8 rtol=atol=1e-15"] = lagjax_run(
        scene, ts, diffrax.Dopri8(), rtol=1e-15, atol=1e-15, max_steps=10**6
    )
    rows["REBOUND IAS15"] = rebound_run(scene, ts)
    rows["heyoka tol=1e-16"] = heyoka_run(scene, ts)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", help="write the rows here")
    options = parser.parse_args()
    os.sched_setaffinity(0, {0})
    lj.enable_fast_cpu_loops()
    jax.config.update("jax_enable_x64", True)
    scene = PythagoreanThreeBody()
    ts = np.arange(0.0, (COMPARE_AT if options.quick else 70) + 1)
    reference = None
    rows = []
    for name, run in runs(scene, ts, options.quick).items():
        if run is None:
            continue
        q, p, first, warm = timed(run, 1 if options.quick else 3)
        if name == "REBOUND IAS15":
            reference = q[COMPARE_AT]
        row = dict(method=name, t1=float(ts[-1]), first_s=first, run_s=warm)
        row.update(measures(scene, q, p), state_at_30=q[COMPARE_AT].tolist())
        rows.append(row)
        print(f"{name:38s} run {warm * 1e3:8.1f} ms (first {first:5.1f} s)  "
              f"energy {row['energy']:.1e} (end {row['energy_end']:.1e})  "
              f"P {row['momentum']:.0e}  L {row['angular_momentum']:.0e}  "
              f"E_rel(m=3) {row['escape_energy']:+.3f}  "
              f"receding {row['receding']}", flush=True)  # fmt: skip
    if reference is not None:
        print(f"position at t = {COMPARE_AT} against REBOUND IAS15:")
        for row in rows:
            row["ias15_difference_at_30"] = float(
                np.max(np.abs(np.asarray(row["state_at_30"]) - reference))
            )
            print(f"  {row['method']:38s} {row['ias15_difference_at_30']:.1e}")
    if options.json:
        meta = dict(mode="quick" if options.quick else "full")
        with open(options.json, "w") as file:
            json.dump(dict(meta=meta, rows=rows), file, indent=1)


if __name__ == "__main__":
    main()
