r"""Stability suite: stiff and extreme problems, and what each method makes of them.

Every attempt ends in one of three outcomes, judged by physics — an exact solution
where there is one, otherwise a float64 reference (Dopri8 at rtol = 10⁻¹²):

- **accurate**: the case's measured error is within its bound (for most cases the
  relative error of the final (q, q̇));
- **degraded**: the run finished with a finite result beyond that bound;
- **refused**: lagjax (or diffrax) raised an error, or the result was not finite —
  its one-line reason is shown, so the table also says whether that reason is clear.

Cases (`stability_stiff.py`): the stiff Fermi–Pasta–Ulam chain at ω = 50, 10³ and
10⁴; a heavily overdamped oscillator (ζ = 10² and 10⁴, where the implicit Kvaerno5
must beat the explicit methods); a pendulum on a stiff spring; a pendulum released at
179.9° (compared with itself one exact period later); a Kepler orbit with e = 0.99;
and singular or near-singular mass matrices (a degenerate Lagrangian, a free body in
Euler angles next to gimbal lock — with the quaternion route as the remedy).

Extreme cases: a Kepler orbit with e = 0.999 against Kepler's equation (periapsis
speed 45× the circular speed); a pendulum 10⁻⁹ below the separatrix, back at its
turning point after one exact period, and the AGM period it relies on checked against
the series at m → 1; a Foucault pendulum whose precession (Ω = 7·10⁻⁵ rad/s) is
measured over thousands of swings at 1 rad/s (`stability_extreme.py`). Round-off
over 10⁶ periods of a harmonic oscillator — the growth exponent of the splitting
methods' energy error, with and without compensated summation, against Brouwer's ½
(`stability_brouwer.py`). The chaotic double pendulum's finite-time Lyapunov
exponent by tangent propagation (`jax.jvp` through `lj.simulate`) per method, and by
two nearby trajectories (`stability_lyapunov.py`).

Every row has the same keys (`stability_engine.ROW_KEYS`); `measure` says in words
what a case measured where the error alone does not (a rate, an exponent).
`--quick` runs a subset and skips the energy-error runs (`energy` is NaN there).
Prints the table and writes `stability.csv` and `stability.json` to `--out`.

    python -m benchmarks.stability [--quick] [--out DIR]

References: Hairer & Wanner, *Solving Ordinary Differential Equations II*, 2nd ed.,
Springer 1996, §IV.1–IV.3 (stiffness, A- and L-stability); Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, 2nd ed., Springer 2006, §XIII (highly oscillatory
problems, FPU) and §VIII.5 (round-off, Brouwer's law); Benettin, Galgani, Giorgilli &
Strelcyn, Meccanica 15, 9 (1980) (Lyapunov exponents by tangent maps).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

from benchmarks.stability_brouwer import brouwer_study  # noqa: E402
from benchmarks.stability_engine import ROW_KEYS, Case, Study  # noqa: E402
from benchmarks.stability_extreme import (  # noqa: E402
    PeriodCheck,
    foucault_study,
    near_collision_kepler_case,
    separatrix_pendulum_case,
)
from benchmarks.stability_float32 import precision_study  # noqa: E402
from benchmarks.stability_lyapunov import lyapunov_study  # noqa: E402
from benchmarks.stability_stiff import (  # noqa: E402
    eccentric_kepler_case,
    fpu_case,
    gimbal_lock_case,
    near_separatrix_case,
    overdamped_case,
    singular_case,
    spring_pendulum_case,
)


def build_cases(quick: bool) -> list[Study]:
    """Every case and study (each has `name` and `rows(timing)`); quick keeps a
    subset with their cheapest telling attempts."""
    if not quick:
        return [
            *(fpu_case(omega) for omega in (50.0, 1e3, 1e4)),
            overdamped_case(1e2), overdamped_case(1e4), spring_pendulum_case(),
            near_separatrix_case(), eccentric_kepler_case(), singular_case(),
            gimbal_lock_case(), near_collision_kepler_case(periods=10), PeriodCheck(),
            separatrix_pendulum_case(), foucault_study(quick), brouwer_study(quick),
            lyapunov_study(quick), precision_study(quick),
        ]  # fmt: skip
    cases = [fpu_case(1e3), overdamped_case(1e2), overdamped_case(1e4),
             singular_case(), gimbal_lock_case(), near_collision_kepler_case(periods=1),
             PeriodCheck(), separatrix_pendulum_case()]  # fmt: skip
    for case in cases:
        if isinstance(case, Case):
            case.attempts = [attempt for attempt in case.attempts if attempt.in_quick]
            # Its own compilation per attempt, for a column the quick tests don't use.
            case.measure_energy = False
    return [*cases, foucault_study(quick), brouwer_study(quick), lyapunov_study(quick),
            precision_study(quick)]  # fmt: skip


def _print_row(row: dict) -> None:
    print(f"{row['case']:44s} {row['method']:34s} {row['outcome']:9s} "
          f"{row['error']:8.1e} {row['energy_error']:8.1e} {row['run_s']:9.2e} "
          f"{row['steps']:8.0f}  "
          f"{row['measure']}{row['reason'][:110]}", flush=True)  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a CI-sized subset")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    options = parser.parse_args(argv)
    options.out.mkdir(parents=True, exist_ok=True)
    timing = dict(repeats=3, max_seconds=0.3 if options.quick else 2.0)
    rows = []
    print(f"{'case':44s} {'method':34s} {'outcome':9s} {'error':>8s} {'energy':>8s} "
          f"{'run s':>9s} {'steps':>8s}  measure / reason")  # fmt: skip
    for case in build_cases(options.quick):
        for row in case.rows(timing):
            rows.append(row)
            _print_row(row)
    with open(options.out / "stability.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(ROW_KEYS))
        writer.writeheader()
        writer.writerows(rows)
    (options.out / "stability.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
