r"""Tolerance runs of gravitating systems: the default `simulate` picks, against Dopri8.

`lj.simulate(system, y0, rtol=r, atol=r)` with no solver: for a Kepler problem
(`KeplerCartesian`, a declared two-body system) below `GEOMETRIC_RTOL` the default
is `TimeTransformed(KahanLi8())` at the fictitious step of
`lagjax._integrate.geometric_choice`; the rows set it against `Dopri8` at the same
rtol = atol, both run by `simulate`, warm (compilation apart), the fastest of five,
one process on one pinned core.

Kepler (GM = a = 1, period 2π) from pericentre, e = 0.5 … 0.9999, 100 periods
(10 with `--quick`, N with `--periods N`; Dopri8 then gets max_steps = 10⁷),
saved at up to 100 apocentres, evenly spread (where the energy is well
conditioned: at e = 0.9999 the pericentre energy cancels 1e4 against 1e4).
Columns: the largest relative energy error over the saves against the energy of
the start state as rounded to float64 (evaluated in extended precision), the largest mean-anomaly error
(rad), the time.

The Pythagorean three-body problem to t = 70 (1400 saves), where the default
stays Dopri8 (three bodies): Dopri8 at rtol against `TimeTransformed(Yoshida4())`
at ds = 0.005 (the best energy of the tables; KahanLi8's floor is 4e-11 there).

References: Mikkola & Tanikawa, Celest. Mech. 74, 287 (1999); Preto & Tremaine,
AJ 118, 2532 (1999).
"""

from __future__ import annotations

import argparse
import json
import time
from functools import partial

import diffrax
import jax
import numpy as np

import lagjax as lj

ECCENTRICITIES = (0.5, 0.9, 0.99, 0.999, 0.9999)
TOLERANCES = (1e-8, 1e-10, 1e-12)


def warm_time(run, repeats: int = 5):
    """(result of the last call, the fastest of `repeats` warm calls in s: the
    machine is shared, and the fastest is the least disturbed)."""
    result = run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        jax.block_until_ready(result.q)
        times.append(time.perf_counter() - start)
    return result, min(times)


def traj_start(e: float) -> tuple[np.ndarray, np.ndarray]:
    q0, p0 = lj.scenes.KeplerCartesian(eccentricity=e).initial_state()
    return np.asarray(q0), np.asarray(p0)


def kepler_errors(traj, e: float) -> dict:
    """Relative energy error against the start's energy in extended precision, and
    the mean-anomaly error (GM = a = 1, so M = t from pericentre)."""
    q, p = np.asarray(traj.q), np.asarray(traj.p)
    # the start state as rounded to float64, its energy in extended precision
    q0, p0 = (np.asarray(x, dtype=np.longdouble) for x in traj_start(e))
    start = float(np.sum(p0 * p0) / 2 - 1 / np.sqrt(np.sum(q0 * q0)))
    energy = 0.5 * np.sum(p**2, -1) - 1 / np.linalg.norm(q, axis=-1)
    anomaly = np.arctan2(q[:, 1] / np.sqrt(1 - e**2), q[:, 0] + e)
    mean = anomaly - e * np.sin(anomaly)
    phase = np.angle(np.exp(1j * (mean - np.asarray(traj.ts))))
    return dict(
        energy=float(np.max(np.abs(energy / start - 1))),
        phase=float(np.max(np.abs(phase))),
    )


def kepler_rows(periods: int) -> list[dict]:
    rows = []
    max_steps = None if periods <= 100 else 10**7
    # apocentres, at most 100 of them
    ts = (np.arange(0, periods, max(1, periods // 100)) + 0.5) * 2 * np.pi
    for e in ECCENTRICITIES:
        scene = lj.scenes.KeplerCartesian(eccentricity=e)
        y0 = scene.initial_state()
        for rtol in TOLERANCES:
            for label, solver in (("default", None), ("Dopri8", diffrax.Dopri8())):
                run = partial(lj.simulate, scene, y0, t1=float(ts[-1]), ts=ts,
                              rtol=rtol, atol=rtol, solver=solver,
                              max_steps=None if solver is None else max_steps)  # fmt: skip
                traj, seconds = warm_time(run)
                rows.append(dict(problem=f"Kepler e={e}", rtol=rtol, run=label,
                                 solver=traj.stats["solver"], seconds=seconds,
                                 steps=int(traj.stats["num_steps"]),
                                 **kepler_errors(traj, e)))  # fmt: skip
                print(json.dumps(rows[-1]), flush=True)
    return rows


def pythagorean_rows(rtol: float) -> list[dict]:
    scene = lj.scenes.PythagoreanThreeBody()
    y0, start = scene.initial_state(), float(scene.energy())
    ts = np.linspace(0.0, 70.0, 1401)[1:]
    runs = {
        "default": dict(rtol=rtol, atol=rtol),
        "TimeTransformed(Yoshida4) ds=0.005": dict(
            dt=0.005, solver=lj.TimeTransformed(lj.Yoshida4())
        ),
    }
    rows = []
    for label, options in runs.items():
        traj, seconds = warm_time(
            partial(lj.simulate, scene, y0, t1=70.0, ts=ts, **options)
        )
        energy = np.max(np.abs(np.asarray(traj.energy()) / start - 1))
        rows.append(dict(problem="Pythagorean", rtol=rtol, run=label,
                         solver=traj.stats["solver"], seconds=seconds,
                         energy=float(energy)))  # fmt: skip
        print(json.dumps(rows[-1]), flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--periods", type=int, default=100)
    options = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    kepler_rows(10 if options.quick else options.periods)
    if not options.quick:
        pythagorean_rows(1e-12)


if __name__ == "__main__":
    main()
