r"""Time-transformed splitting on eccentric Kepler orbits, against Dopri8 and heyoka.

Kepler's problem (GM = a = 1, period 2π) from pericentre, e = 0.99, 0.999 and
0.9999, over 1000 periods (100 with `--quick`), 101 saved states at multiples of 10
periods (at the pericentre, where the energy reads the run's round-off most
enlarged: below). Rows, one pinned core (the first of the inherited affinity:
`taskset -c 1` holds):

- `lj.TimeTransformed(lj.Yoshida4())` and `(lj.KahanLi8())`, the logarithmic
  Hamiltonian, fictitious step ds = 0.05 (dt/ds = r: 126 steps per period at any e);
- `lj.simulate(..., solver=diffrax.Dopri8(), rtol=atol=1e-12)`;
- heyoka's Taylor method at tol 1e-16 (`propagate_grid`), if `import heyoka` works.

The batch: `jax.vmap` of `simulate` with `TimeTransformed(Yoshida4)`, ds = 0.05,
over 1024 eccentricities evenly spaced in [0.5, 0.999], the same saves (`--quick`:
10 periods, a save per period); the largest energy error and pericentre drift over
the batch and the time per member (against one trajectory of the same method).

Columns: warm run time (median of five, three with `--quick`; compilation apart),
the largest relative energy error over the saves, the pericentre (Runge–Lenz) drift in rad, and the
position error against Kepler's equation (the timing).

`--round-off`: where the energy error comes from (`round_off_rows`), on 32 orbits
with e in [0.99, 0.99001] and at pericentre and apocentre saves of e = 0.99.

Measured (full mode, 2026-11-27, core 0 pinned, load ≈ 3.6: times inflated about
twofold, read the ratios; heyoka's own row is its energy at tol 1e-16):

| e | TimeTransformed(Yoshida4) | TimeTransformed(KahanLi8) | heyoka |
|---|---|---|---|
| 0.99 | 80 ms (0.33×), 3.6e-12, 3.6e-13 rad | 107 ms (0.44×), 2.2e-12, 2.7e-13 rad | 240 ms, 1.3e-12, 2.4e-14 rad |
| 0.999 | 74 ms (0.16×), 9.2e-12, 4.1e-13 rad | 315 ms (0.69×), 8.0e-11, 3.3e-13 rad | 456 ms, 6.3e-11, 3.3e-14 rad |
| 0.9999 | 88 ms (0.16×), 1.2e-11, 4.6e-13 rad | 345 ms (0.61×), 1.3e-9, 3.7e-13 rad | 565 ms, 2.8e-10, 2.4e-14 rad |

(time and its ratio to heyoka, relative energy error, pericentre drift.) Again
2026-11-27, core 0, load ≈ 5 (times inflated threefold), Yoshida4 and heyoka
alone: 0.25×, 0.21×, 0.15× heyoka's time, the same energies and drifts. Every
time-transformed row is faster than heyoka and keeps the drift below 1e-10 rad;
none keeps the energy to 1e-12 at these saves — nor does heyoka past e = 0.99.
Dopri8 at 1e-12: 1.7–2.5× heyoka's time, energy 8e-10–1e-7, drift 3e-10 rad.

The full mode again after the change below (2026-11-27 21:24, core 1, load ≈ 2,
heyoka slow in this run: 360, 241, 381 ms): Yoshida4 24, 66, 48 ms, KahanLi8 99,
312, 206 ms, Dopri8 648, 500, 638 ms, every energy and drift as in the table.
The batch: 1024 orbits over 1000 periods in 17.2 s, 16.8 ms a member against
24.1 ms for one trajectory (e = 0.99, the same 126 steps a period) in the same
run: 0.70× (0.31× in another process at load ≈ 3.5: 19.7 against 63 ms); largest
energy error 8.1e-12, largest pericentre drift 4.6e-13 rad. Before the run kept
its saves out of the loop's state
(`lagjax._integrate.time_transformed_run._walk_to_saves`), `vmap` selected the
101 save slots at every step: 9.6 s for 10 periods of the batch (0.45 s after),
and the full mode did not finish in half an hour.

**Where the energy error comes from** (`--round-off`, 2026-11-27, core 0, load ≈
3.6; ε = 2.2e-16). The saves fall on the pericentre, and there the energy reads
the round-off enlarged:

- not the energy's evaluation: the same states evaluated in long double give the
  same error (2.76e-12 at the pericentre saves of e = 0.99, both ways);
- not the saves: the states of all 125,660 steps, without partial steps, reach the
  same 5e-12 near the pericentre (1000 periods, ds = 0.05);
- the round-off of the run, read through the quantity the method keeps. The
  logarithmic leapfrog keeps $\Gamma = \ln((T + p_t)\,r)$ exactly in exact
  arithmetic (a long-double run of the same map keeps the energy to 1e-16 through
  a pericentre); round-off walks $\Gamma$, and a state with $\Gamma \ne 0$ lies on
  the Kepler orbit of $GM = e^\Gamma$ with energy $-p_t$, so
  $H + p_t = \Gamma/r$: relative $2\Gamma/(1 - e)$ at the pericentre (200× at e =
  0.99), $\Gamma/2$ at the apocentre. At the apocentre saves the error is 3.3e-14,
  the rounding of $p_t = -H(q_0, p_0)$ itself.

| Yoshida4, ds = 0.05, 32 orbits | Kahan's sum (the default) | plain sum |
|---|---|---|
| rms Γ after 10 / 100 / 1000 periods | 8.7 / 22 / 97 ε | 23 / 49 / 251 ε |
| mean Γ after 1000 periods (a trend) | 0.6 ε | 12 ε |
| energy at the pericentre / apocentre saves (e = 0.99) | 2.8e-12 / 3.3e-14 | 4.3e-12 / 3.7e-14 |

Kahan's sum (`compensated=True`, the splitting tables' default, on in every row
above) removes the part of the ~118 steps a period away from the pericentre. What
is left is the round-off of the increments themselves in the ~8 steps a period
near the pericentre, where a step moves the state by as much as its size: no
summation reaches it (carrying the compensation through the step's Jacobian as
well, a `jax.jvp` a step, gave 69 ε against 79 on a hand-written twin). It grows
as √n (a random walk; the ensemble mean stays at 0.6 ε: no secular trend) and
falls slowly with the step: ds = 0.0125, four times the steps, 39 ε, 1.7e-12 rms
at the pericentre. So at e = 0.99 the 1e-12 target at pericentre saves is below
what float64 steps reach in heyoka's time (heyoka reads 1.3e-12 there); at
e = 0.999 and 0.9999 the state's own rounding at the pericentre (½ ulp of
|p| ≈ 45 and 141) is already 3e-13 and 4e-12 of the energy.

References: Mikkola & Tanikawa, Celest. Mech. 74, 287 (1999); Preto & Tremaine,
AJ 118, 2532 (1999); Biscani & Izzo, MNRAS 504, 2614 (2021).
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Callable

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from benchmarks.state_timing import timed

PERIOD = 2 * np.pi
BATCH = 1024


def kepler() -> lj.SeparableHamiltonian:
    return lj.SeparableHamiltonian(lambda p: p @ p / 2, lambda q: -1 / jnp.sqrt(q @ q))


# One system for every row: a method compiles once for all eccentricities.
KEPLER = kepler()


def pericentre_state(e: float) -> tuple[np.ndarray, np.ndarray]:
    return np.array([1 - e, 0.0]), np.array([0.0, np.sqrt((1 + e) / (1 - e))])


def kepler_position(t: np.ndarray, e: float) -> np.ndarray:
    """From pericentre: M = t = E − e sin E, q = (cos E − e, √(1−e²) sin E)."""
    eccentric = t + e * np.sin(t)
    for _ in range(100):
        eccentric -= (eccentric - e * np.sin(eccentric) - t) / (
            1 - e * np.cos(eccentric)
        )
    return np.stack([np.cos(eccentric) - e, np.sqrt(1 - e**2) * np.sin(eccentric)], 1)


def conserved_errors(q: np.ndarray, p: np.ndarray) -> dict:
    """The largest relative energy error and Runge–Lenz (pericentre) angle over
    states (..., 2) of orbits started at pericentre on the x-axis (E = −1/2)."""
    energy = 0.5 * np.sum(p**2, -1) - 1 / np.linalg.norm(q, axis=-1)
    angular = q[..., 0] * p[..., 1] - q[..., 1] * p[..., 0]
    r = np.linalg.norm(q, axis=-1)
    lenz = np.arctan2(
        -p[..., 0] * angular - q[..., 1] / r, p[..., 1] * angular - q[..., 0] / r
    )
    return dict(
        energy=float(np.max(np.abs(energy / -0.5 - 1))),
        pericentre_drift=float(np.max(np.abs(lenz))),
    )


def measures(q: np.ndarray, p: np.ndarray, ts: np.ndarray, e: float) -> dict:
    return dict(
        **conserved_errors(q, p),
        position=float(np.max(np.abs(q - kepler_position(ts, e)))),
    )


def lagjax_run(e: float, ts: np.ndarray, solver, **options) -> Callable:
    y0, system = pericentre_state(e), KEPLER

    def run():
        traj = lj.simulate(system, y0, t1=float(ts[-1]), ts=ts, solver=solver,
                           **options)  # fmt: skip
        return np.asarray(traj.q), np.asarray(traj.p)

    return run


def batch_run(eccentricities: np.ndarray, ts: np.ndarray, solver, ds: float):
    """One compiled `jax.vmap` of `simulate` over the starts of all eccentricities."""
    system = KEPLER
    starts = tuple(np.stack(x) for x in zip(*map(pericentre_state, eccentricities)))

    @jax.jit
    def batch(y0):
        def one(start):
            traj = lj.simulate(system, start, t1=float(ts[-1]), ts=ts, dt=ds,
                               solver=solver)  # fmt: skip
            return traj.q, traj.p

        return jax.vmap(one)(y0)

    def run():
        q, p = batch(starts)
        return np.asarray(q), np.asarray(p)

    return run


def heyoka_run(e: float, ts: np.ndarray) -> Callable | None:
    try:
        import heyoka as hy
    except ImportError:
        return None
    x, y, vx, vy = hy.make_vars("x", "y", "vx", "vy")
    r3 = (x**2 + y**2) ** 1.5
    system = [(x, vx), (y, vy), (vx, -x / r3), (vy, -y / r3)]
    q0, p0 = pericentre_state(e)
    start = np.concatenate([q0, p0])
    integrator = hy.taylor_adaptive(system, start, tol=1e-16)

    def run():
        integrator.time = 0.0
        integrator.state[:] = start
        states = integrator.propagate_grid(ts)[-1]
        return states[:, :2], states[:, 2:]

    return run


def single_rows(ts: np.ndarray, periods: int, repeats: int) -> list[dict]:
    rows = []
    for e in (0.99, 0.999, 0.9999):
        runs = {
            "TimeTransformed(Yoshida4) ds=0.05": lagjax_run(
                e, ts, lj.TimeTransformed(lj.Yoshida4()), dt=0.05
            ),
            "TimeTransformed(KahanLi8) ds=0.05": lagjax_run(
                e, ts, lj.TimeTransformed(lj.KahanLi8()), dt=0.05
            ),
            "Dopri8 rtol=atol=1e-12": lagjax_run(
                e, ts, diffrax.Dopri8(), rtol=1e-12, atol=1e-12, max_steps=10**7
            ),
            "heyoka tol=1e-16": heyoka_run(e, ts),
        }
        for name, run in runs.items():
            if run is None:
                continue
            q, p, first, warm = timed(run, repeats)
            row = dict(e=e, periods=periods, method=name, first_s=first, run_s=warm)
            row.update(measures(q, p, ts, e))
            rows.append(row)
            print(f"e={e:<6} {name:36s} run {warm * 1e3:9.1f} ms (first "
                  f"{first:5.1f} s)  energy {row['energy']:.1e}  pericentre "
                  f"{row['pericentre_drift']:.1e} rad  position "
                  f"{row['position']:.1e}", flush=True)  # fmt: skip
    return rows


def batch_row(ts: np.ndarray, periods: int, repeats: int) -> dict:
    eccentricities = np.linspace(0.5, 0.999, BATCH)
    run = batch_run(eccentricities, ts, lj.TimeTransformed(lj.Yoshida4()), ds=0.05)
    q, p, first, warm = timed(run, repeats)
    row = dict(e=[0.5, 0.999], periods=periods, batch=BATCH, first_s=first,
               method=f"TimeTransformed(Yoshida4) ds=0.05 vmap x{BATCH}",
               run_s=warm, per_member_s=warm / BATCH)  # fmt: skip
    row.update(conserved_errors(q, p))
    print(f"e in [0.5, 0.999] x{BATCH} TimeTransformed(Yoshida4) ds=0.05 run "
          f"{warm * 1e3:9.1f} ms, {warm / BATCH * 1e3:.2f} ms per member (first "
          f"{first:5.1f} s)  max energy {row['energy']:.1e}  max pericentre "
          f"{row['pericentre_drift']:.1e} rad", flush=True)  # fmt: skip
    return row


def log_hamiltonian(q: np.ndarray, p: np.ndarray, p_t: np.ndarray) -> np.ndarray:
    """Γ = ln((T + p_t)·r) in long double: zero on the start's shell, kept exactly
    by the logarithmic leapfrog on Kepler's problem; a state with Γ ≠ 0 is on the
    Kepler orbit of GM = e^Γ with energy −p_t, so H − E = Γ/r to first order."""
    q, p = q.astype(np.longdouble), p.astype(np.longdouble)
    kinetic = np.sum(p * p, -1) / 2
    return np.log((kinetic + p_t) * np.sqrt(np.sum(q * q, -1))).astype(float)


def round_off_rows(periods: int) -> list[dict]:
    """Where the energy error comes from (`--round-off`): 32 orbits with e in
    [0.99, 0.99001], `TimeTransformed(Yoshida4)` at ds = 0.05 with and without
    Kahan's sum; the log-Hamiltonian Γ half a period before the end (at the
    apocentre, in long double), its ensemble mean (a secular trend) and rms after
    periods/100, /10 and all; and the energy of the first orbit at the pericentre
    saves (in float64 and in long double) and at the apocentre ones."""
    eccentricities = np.linspace(0.99, 0.99001, 32)
    starts = tuple(np.stack(x) for x in zip(*map(pericentre_state, eccentricities)))
    q0, p0 = starts
    p_t = -(np.sum(p0**2, -1) / 2 - 1 / np.linalg.norm(q0, axis=-1))  # as the run
    rows = []
    for compensated in (True, False):
        solver = lj.TimeTransformed(lj.Yoshida4(compensated=compensated))
        row = dict(method=f"Yoshida4 ds=0.05 compensated={compensated}")
        for fraction in (100, 10, 1):
            span = (periods // fraction - 0.5) * PERIOD
            batch = jax.jit(jax.vmap(lambda s, t1=span, solver=solver: lj.simulate(
                KEPLER, s, t1=t1, dt=0.05, solver=solver).ys))  # fmt: skip
            q, p = (np.asarray(x)[:, -1] for x in batch(starts))
            gamma = log_hamiltonian(q, p, p_t)
            row[f"gamma_rms_{periods // fraction}"] = float(np.sqrt(np.mean(gamma**2)))
            row[f"gamma_mean_{periods // fraction}"] = float(np.mean(gamma))
        for place, offset in (("pericentre", 0.0), ("apocentre", 0.5)):
            ts = (np.linspace(0, periods, 11)[1:] - offset) * PERIOD
            traj = lj.simulate(KEPLER, pericentre_state(0.99), t1=ts[-1], ts=ts,
                               dt=0.05, solver=solver)  # fmt: skip
            q, p = np.asarray(traj.q), np.asarray(traj.p)
            row[f"energy_{place}"] = conserved_errors(q, p)["energy"]
            q, p = q.astype(np.longdouble), p.astype(np.longdouble)
            energy = np.sum(p * p, -1) / 2 - 1 / np.sqrt(np.sum(q * q, -1))
            row[f"energy_{place}_long_double"] = float(
                np.max(np.abs(energy / -0.5 - 1))
            )
        print(row, flush=True)
        rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument(
        "--round-off", action="store_true", help="only the round-off analysis"
    )
    parser.add_argument("--json", help="write the rows here")
    options = parser.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # taskset -c 1 holds
    lj.enable_fast_cpu_loops()
    jax.config.update("jax_enable_x64", True)
    periods = 100 if options.quick else 1000
    repeats = 3 if options.quick else 5
    ts = np.linspace(0, periods * PERIOD, 101)
    if options.round_off:
        rows = round_off_rows(periods)
    else:
        rows = single_rows(ts, periods, repeats)
        if options.quick:  # the batch over 10 periods, saved once a period
            periods, ts = 10, np.linspace(0, 10 * PERIOD, 11)
        rows.append(batch_row(ts, periods, 1 if options.quick else 3))
    if options.json:
        meta = dict(mode="quick" if options.quick else "full")
        with open(options.json, "w") as file:
            json.dump(dict(meta=meta, rows=rows), file, indent=1)


if __name__ == "__main__":
    main()
