r"""The Pythagorean problem in a chain of closest pairs, against heyoka and IAS15.

Burrau's three bodies (`lagjax.scenes.pythagorean`) to t = 70, saved at
t = 0, 1, …, 70, run through `lj.simulate` on the scene itself with
`lj.ChainRegularization(GraggBulirschStoer(rtol=atol=tol))` (the logarithmic
leapfrog, extrapolated, in chain coordinates re-formed as the closest pairs
change: `lagjax.solvers.chain`), against:

- the same extrapolated leapfrog in the scene's barycentric coordinates,
  `lj.TimeTransformed(GraggBulirschStoer(...))`, whose energy error has a floor
  set by the round-off of the close pair's separation, $\varepsilon|q|/r$;
- heyoka's Taylor method on hand-written equations (tol 1e-16) and REBOUND's
  IAS15 (the `bench` extra; `benchmarks.close_encounters` builds both).

Each configuration is run as given and shifted by +10 and +100 in every
coordinate (the same dynamics; the barycentric separations then lose one and two
more digits, the chain's do not). The lagjax rows run inside `jax.jit` (one
compilation per solver, shared by the shifts; the eager `simulate` call adds its
checks, one eager row shows how much). One pinned core; the rows timed in turn
for `ROUNDS` rounds, the fastest of each, so the ratios are of one process under
one load; compilation is timed apart (the first call).

Columns: warm time and its ratio to heyoka's on the same configuration, steps
(refused), re-chainings, the largest relative energy error over the saves, the
largest |P| and |L|, the largest position difference at t = 30 from IAS15 on the
unshifted configuration (shifted states shifted back), and the escape (the
lightest body's energy relative to the binary at t = 70, positive: it escapes).

2026-11-27, core 1 pinned, the other core busy (load ≈ 2.7; heyoka at 31 ms,
twice its quiet time), seven interleaved rounds, the fastest of each, inside
`jax.jit` unless marked:

| configuration | method | time | / heyoka | energy | Δq(t=30) | steps (refused) |
|---|---|---|---|---|---|---|
| as given | chain GBS tol 1e-13 | 14.5 ms | 0.47 | 1.1e-12 | 3.7e-9 | 3,318 (212) |
| as given | chain GBS tol 3e-14 | 15.8 ms | 0.52 | 3.1e-13 | 3.7e-9 | 3,896 (210) |
| as given | chain GBS tol 1e-14 | 16.0 ms | 0.52 | 1.2e-13 | 3.7e-9 | 4,483 (176) |
| as given | chain GBS tol 3e-14, eager | 27.9 ms | 0.91 | 3.1e-13 | 3.7e-9 | |
| as given | Jacobi GBS tol 3e-14 | 16.7 ms | 0.55 | 2.6e-13 | 3.7e-9 | 3,915 (198) |
| as given | barycentric GBS tol 3e-14 | 18.0 ms | 0.59 | 6.5e-13 | 3.7e-9 | 3,976 (199) |
| as given | heyoka tol 1e-16 | 30.6 ms | 1 | 1.4e-9 | 5.5e-8 | |
| as given | IAS15 | 95.4 ms | 3.1 | 9.9e-11 | 0 | |
| +10 | chain GBS tol 3e-14 | 15.5 ms | 0.61 | 2.5e-13 | 3.7e-9 | |
| +10 | barycentric GBS tol 3e-14 | 22.1 ms | 0.87 | 3.0e-11 | 3.6e-9 | |
| +10 | heyoka tol 1e-16 | 25.5 ms | 1 | 8.4e-9 | 3.2e-7 | |
| +10 | IAS15 | 95.5 ms | 3.8 | 4.7e-10 | 1.1e-8 | |
| +100 | chain GBS tol 3e-14 | 15.7 ms | 0.04 | 4.9e-13 | 3.7e-9 | |
| +100 | barycentric GBS tol 3e-14 | 18.2 ms | 0.04 | 6.1e-11 | 3.9e-9 | |
| +100 | heyoka tol 1e-16 | 405 ms | 1 | 3.5e-5 | 3.6e-6 | |
| +100 | IAS15 | 81.9 ms | 0.20 | 1.2e-8 | 4.4e-7 | |

Every chain row re-formed its chain 91 times, kept |P| ≤ 4e-15 and |L| ≤ 2e-13,
and saw the lightest body escape (E_rel = +5.283); on the shifted configurations
it took the same steps as on the given one. The chain costs what the fixed
Jacobi coordinates cost (0.95× their time), and less than the barycentric run
(0.88×, 4.1 against 4.5 µs a step). An earlier run of the same rows (load ≈ 2.4,
heyoka at 46 ms) gave 0.28×, 0.36× and 0.40× heyoka at tol 1e-13, 3e-14, 1e-14.
Compilation (the earlier run): 3.0–3.3 s per tolerance, 1.3–1.5× the barycentric
run's 2.3 s (the first row 6.9 s, with the process's warm-up).
Shifted by 100, heyoka's run at tol 1e-16 takes 13× longer and lets the
lightest body escape with E_rel = +44 (its separations lose two digits too).

The energies above are at t = 0, 1, …, 70. Saved every 0.05 instead, a save that
falls inside a close pericentre passage of the escaping binary reads more:
5.0e-11 at t = 62.35 (tol 1e-13; 1.6e-11 barycentric), where r = 7.6e-3 and
U = −V ≈ 2600. The logarithmic Hamiltonian keeps Γ = ln((T + p_t)/U) to ~2e-13
there, so H − E ≈ U·δΓ while U is large; the error returns to ~1e-12 after the
passage (8.1e-13 at t = 70).

References: Mikkola & Aarseth, Celest. Mech. 57, 439 (1993); Mikkola & Merritt,
AJ 135, 2398 (2008); Rein & Spiegel, MNRAS 446, 1424 (2015) (IAS15); Biscani &
Izzo, MNRAS 504, 2614 (2021) (heyoka).
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Callable
from types import SimpleNamespace

import jax
import numpy as np

import lagjax as lj
from benchmarks.close_encounters import interleaved, measures
from benchmarks.pythagorean_jacobi import jacobi_run
from benchmarks.pythagorean_peers import heyoka_run, rebound_run
from lagjax.scenes.pythagorean import PythagoreanThreeBody

COMPARE_AT = 30
SHIFTS = (0.0, 10.0, 100.0)
CHAIN_TOLERANCES = (1e-13, 3e-14, 1e-14)
BARYCENTRIC_TOLERANCE = 3e-14
FIRST_STEP = 0.1  # the first fictitious step; the controller takes over
ROUNDS = 7


def shifted_scene(scene: PythagoreanThreeBody, shift: float) -> SimpleNamespace:
    """What the peers' builders read of a scene, its start shifted by `shift`."""
    q0, p0 = scene.initial_state()
    return SimpleNamespace(
        masses=scene.masses,
        gravitational_constant=scene.gravitational_constant,
        initial_state=lambda: (q0 + shift, p0),
    )


def jitted(scene, ts: np.ndarray, solver) -> Callable:
    """`simulate` of the scene with `solver` inside `jax.jit`, a function of y0."""

    @jax.jit
    def go(y0):
        traj = lj.simulate(scene, y0, t1=float(ts[-1]), ts=ts, dt=FIRST_STEP,
                           solver=solver)  # fmt: skip
        stats = traj.stats
        rechains = stats.get("num_rechains", stats["num_steps"] * 0)
        return (traj.q, traj.p, stats["num_steps"], stats["num_rejected_steps"],
                rechains)  # fmt: skip

    return go


def library_run(scene, go: Callable, y0) -> Callable:
    def run():
        q, p, *counts = jax.block_until_ready(go(y0))
        run.steps, run.rejected, run.rechains = (int(c) for c in counts)  # pyright: ignore
        return np.asarray(q), np.asarray(p)

    return run


def eager_run(scene, ts: np.ndarray, solver, y0) -> Callable:
    def run():
        traj = lj.simulate(scene, y0, t1=float(ts[-1]), ts=ts, dt=FIRST_STEP,
                           solver=solver)  # fmt: skip
        run.steps = int(traj.stats["num_steps"])  # pyright: ignore
        run.rejected = int(traj.stats["num_rejected_steps"])  # pyright: ignore
        run.rechains = int(traj.stats["num_rechains"])  # pyright: ignore
        return np.asarray(traj.q), np.asarray(traj.p)

    return run


def chain_solver(tol: float) -> lj.ChainRegularization:
    return lj.ChainRegularization(lj.GraggBulirschStoer(rtol=tol, atol=tol))


def rows_to_time(scene, ts: np.ndarray, shifts, tolerances) -> dict:
    """{(shift, name): run}: the chain at each tolerance, the barycentric run and
    the peers on each shifted configuration, and one eager chain row."""
    chains = {tol: jitted(scene, ts, chain_solver(tol)) for tol in tolerances}
    barycentric = jitted(scene, ts, lj.TimeTransformed(lj.GraggBulirschStoer(
        rtol=BARYCENTRIC_TOLERANCE, atol=BARYCENTRIC_TOLERANCE)))  # fmt: skip
    rows: dict = {}
    for shift in shifts:
        moved = shifted_scene(scene, shift)
        y0 = moved.initial_state()
        for tol, go in chains.items():
            rows[(shift, f"chain GBS tol={tol:.0e} jit")] = library_run(scene, go, y0)
        name = f"barycentric GBS tol={BARYCENTRIC_TOLERANCE:.0e} jit"
        rows[(shift, name)] = library_run(scene, barycentric, y0)
        for name, build in (("heyoka tol=1e-16", heyoka_run),
                            ("REBOUND IAS15", rebound_run)):  # fmt: skip
            run = build(moved, ts)
            if run is not None:
                rows[(shift, name)] = run
    tol = tolerances[len(tolerances) // 2]
    rows[(shifts[0], f"chain GBS tol={tol:.0e} eager")] = eager_run(
        scene, ts, chain_solver(tol), scene.initial_state()
    )
    # Fixed Jacobi coordinates with the 4-5 pair inside, written for this problem
    # alone (`benchmarks.pythagorean_jacobi`): what the chain's generality costs.
    solver = lj.TimeTransformed(lj.GraggBulirschStoer(rtol=tol, atol=tol))
    rows[(shifts[0], f"Jacobi GBS tol={tol:.0e} jit")] = jacobi_run(
        scene, ts, solver, FIRST_STEP, True
    )
    return rows


def report(scene, rows: dict, timings: dict) -> list[dict]:
    reference = timings.get((0.0, "REBOUND IAS15"))
    reference = None if reference is None else reference[2][0][COMPARE_AT]
    table = []
    for (shift, name), (first, warm, (q, p)) in timings.items():
        heyoka = timings.get((shift, "heyoka tol=1e-16"))
        run = rows[(shift, name)]
        row = dict(shift=shift, method=name, first_s=first, run_s=warm,
                   heyoka_ratio=None if heyoka is None else warm / heyoka[1],
                   steps=getattr(run, "steps", None),
                   rejected=getattr(run, "rejected", None),
                   rechains=getattr(run, "rechains", None),
                   **measures(scene, q - shift, p))  # fmt: skip
        if reference is not None:
            row["ias15_difference_at_30"] = float(
                np.max(np.abs(q[COMPARE_AT] - shift - reference))
            )
        table.append(row)
        ratio = "" if heyoka is None else f" {row['heyoka_ratio']:5.2f}x heyoka"
        counts = "" if row["steps"] is None else (
            f" {row['steps']} steps ({row['rejected']} refused"
            + ("" if row["rechains"] is None else f", {row['rechains']} re-chained")
            + ")")  # fmt: skip
        print(f"+{shift:<5g} {name:34s} {warm * 1e3:7.2f} ms (first {first:5.2f} s)"
              f"{ratio}  energy {row['energy']:.1e}  P {row['momentum']:.0e}  "
              f"L {row['angular_momentum']:.0e}  dq(30) "
              f"{row.get('ias15_difference_at_30', float('nan')):.1e}  "
              f"E_rel {row['escape_energy']:+.3f}{counts}", flush=True)  # fmt: skip
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="to t = 30, no shifts, one tolerance, one round")  # fmt: skip
    parser.add_argument("--json", help="write the rows here")
    options = parser.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # taskset -c 1 holds
    lj.enable_fast_cpu_loops()
    jax.config.update("jax_enable_x64", True)
    scene = PythagoreanThreeBody()
    ts = np.arange(0.0, (COMPARE_AT if options.quick else 70) + 1)
    shifts = SHIFTS[:1] if options.quick else SHIFTS
    tolerances = CHAIN_TOLERANCES[1:2] if options.quick else CHAIN_TOLERANCES
    rows = rows_to_time(scene, ts, shifts, tolerances)
    timings = interleaved(rows, 1 if options.quick else ROUNDS)
    table = report(scene, rows, timings)
    if options.json:
        with open(options.json, "w") as file:
            json.dump(dict(mode="quick" if options.quick else "full", rows=table),
                      file, indent=1)  # fmt: skip


if __name__ == "__main__":
    main()
