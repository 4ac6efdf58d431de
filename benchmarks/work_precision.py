r"""Work-precision report: error against run time for every scene, solver and peer.

For each scene, every solver family is swept — step counts for fixed-step solvers,
tolerances (rtol = atol) for adaptive ones — and every point is measured the same
way (`lagjax.diagnostics`): compile time apart, run time the median of warm runs
ended by `block_until_ready`, the relative error of the final (q, q̇) against the
exact solution or a float64 reference (Dopri8 at rtol = 10⁻¹⁴; its difference from
rtol = 10⁻¹³ is reported as the reference's floor), and the maximum relative energy
error along the run (from a second, untimed run saved at 200 stratified random
times on the step grid, `diagnostics.sample_times`). Peers run beside lagjax in the
same process (`peers.py`): the equations written by hand and integrated with
diffrax, scipy's `solve_ivp` on numpy right-hand sides, and the SymPy route with
its derivation time. The scaling and throughput studies are in `scaling.py`.

Writes to `--out` (default `benchmarks/results/`): `work_precision.csv`,
`report.json`, one `wp_<scene>.png` per scene and `summary.md` (the fastest method
per scene and error level, peer ratios), plus what `scaling.py` writes.

    python benchmarks/work_precision.py [--quick] [--out DIR] [--skip-scaling]

References: Hairer, Nørsett & Wanner, *Solving Ordinary Differential Equations I*,
2nd ed., §II.10 (work-precision diagrams); Hairer, Lubich & Wanner, *Geometric
Numerical Integration*, 2nd ed., §I.2 (Hénon–Heiles), §I.5 (Fermi–Pasta–Ulam).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

sys.path.insert(0, str(Path(__file__).resolve().parent))  # peers, scaling

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import peers  # noqa: E402

import lagjax as lj  # noqa: E402
from lagjax import diagnostics  # noqa: E402
from lagjax.rigid import quaternion_to_matrix  # noqa: E402
from lagjax.scenes.base import AbstractScene  # noqa: E402
from lagjax.scenes.central import KeplerCartesian  # noqa: E402
from lagjax.scenes.chains import FermiPastaUlamChain  # noqa: E402
from lagjax.scenes.earth import FoucaultPendulum  # noqa: E402
from lagjax.scenes.pendulums import DoublePendulum, SimplePendulum  # noqa: E402
from lagjax.scenes.rigid import TorqueFreeBody  # noqa: E402
from lagjax.solvers.rigid import (  # noqa: E402
    QuaternionProjection,
    RigidBodyVerlet,
    RigidBodyYoshida4,
)

ENERGY_SAMPLES = 200  # stratified random save times (diagnostics.sample_times)
REFERENCE_RTOL = (1e-13, 1e-14)
ERROR_LEVELS = (1e-3, 1e-6, 1e-9)


class HenonHeiles(AbstractScene):
    r"""Hénon–Heiles, $H = \tfrac12|p|^2 + \tfrac12(x^2 + y^2) + x^2y - y^3/3$.

    From q = (0.1, 0), p = (0, 0.5): E = 0.13 < 1/6, a bounded orbit (GNI §I.2).
    """

    default_t1: ClassVar[float] = 100.0
    default_dt: ClassVar[float] = 0.01

    def system(self) -> lj.SeparableHamiltonian:
        return lj.SeparableHamiltonian(
            lambda p, t, args: 0.5 * jnp.sum(p**2),
            lambda q, t, args: (
                0.5 * (q[0] ** 2 + q[1] ** 2) + q[0] ** 2 * q[1] - q[1] ** 3 / 3
            ),
        )

    def initial_state(self):
        return jnp.array([0.1, 0.0]), jnp.array([0.0, 0.5])


def comparable(q: Any, qdot: Any) -> jax.Array:
    return jnp.concatenate([jnp.ravel(q), jnp.ravel(qdot)])


def position_and_velocity(trajectory: Any) -> jax.Array:
    return jax.vmap(comparable)(trajectory.q, trajectory.qdot)


def rotation_and_angular_velocity(trajectory: Any) -> jax.Array:
    """(R, ω) of a `RigidBody` run on (quaternion, body momentum Π)."""
    rotation = quaternion_to_matrix(trajectory.q).reshape(-1, 9)
    return jnp.concatenate([rotation, trajectory.ys[1] / trajectory.system.moments], -1)


def simulate_case(case, solver, y0, setting, fixed, saved, max_steps):
    """Comparable states at `saved` (or the end) and the step count, by lj.simulate."""
    kwargs = dict(dt=setting) if fixed else dict(rtol=setting, atol=setting)
    system = case.scene if case.system is None else case.system
    trajectory = lj.simulate(
        system, y0, t1=case.t1, solver=solver, ts=saved, max_steps=max_steps, **kwargs
    )
    return case.states(trajectory), trajectory.stats["num_steps"]


@dataclass
class Case:
    """A scene, its run length, its sweeps and the peer that stands beside it."""

    key: str
    title: str
    scene: Any
    t1: float
    fixed: dict[str, tuple[Any, tuple[int, ...]]]
    adaptive: dict[str, tuple[Any, tuple[float, ...]]]
    peer: peers.Peer
    peer_tolerances: tuple[float, ...]
    scipy_methods: tuple[str, ...] = ("DOP853",)
    exact: np.ndarray | None = None
    system: Any = None  # what lj.simulate integrates; default the scene
    states: Callable[[Any], jax.Array] = position_and_velocity
    initial_state: Any = None

    def start(self) -> Any:
        return (
            self.scene.initial_state()
            if self.initial_state is None
            else self.initial_state
        )


@dataclass(frozen=True)
class Runner:
    """One timed point, `fn(*args)`, and `finish(output)` → (final, series, steps)."""

    fn: Callable[..., Any]
    args: tuple
    jit: bool
    finish: Callable[[Any], tuple[np.ndarray, np.ndarray, int]]
    setup_seconds: float = 0.0


@dataclass(frozen=True)
class Method:
    """One line of a work-precision diagram: a solver swept over `values`."""

    label: str
    family: str  # lagjax | diffrax | scipy | sympy
    parameter: str  # steps | rtol
    values: tuple[float, ...]
    runner: Callable[[float], Runner]


def lagjax_method(case: Case, name: str, solver: Any, fixed: bool, values) -> Method:
    """lagjax on the case; a second, untimed run saves states for the energy error."""
    longest = int(max(values)) + 2 if fixed else 10**6

    def run(y0, setting, ts):
        limit = None if (fixed and ts is None) else longest  # None: the scan path
        return simulate_case(case, solver, y0, setting, fixed, ts, limit)

    probe = jax.jit(lambda y0, setting, ts: run(y0, setting, ts)[0])

    def runner(value: float) -> Runner:
        setting = case.t1 / value if fixed else value
        dt = setting if fixed else None
        saved = diagnostics.sample_times(0.0, case.t1, ENERGY_SAMPLES, dt)

        def finish(output):
            series = np.asarray(probe(case.start(), setting, saved))
            return np.asarray(output[0][-1]), series, int(output[1])

        return Runner(lambda y0: run(y0, setting, None), (case.start(),), True, finish)

    kind = "steps" if fixed else "rtol"
    return Method(f"lagjax {name}", "lagjax", kind, tuple(values), runner)


def diffrax_method(case: Case, name: str, solver: Any) -> Method:
    saved = diagnostics.sample_times(0.0, case.t1, ENERGY_SAMPLES)
    y0 = jnp.asarray(case.peer.initial_state)
    # rtol traced: one compilation of the (untimed) energy run serves every point.
    probe = jax.jit(
        lambda y0, rtol: peers.diffrax_final(case.peer, solver, case.t1, rtol, saved)(
            y0
        )
    )

    def runner(value: float) -> Runner:
        def finish(output):
            return np.asarray(output), np.asarray(probe(y0, value)), -1

        final = peers.diffrax_final(case.peer, solver, case.t1, value)
        return Runner(final, (y0,), True, finish)

    label = f"diffrax {name} (hand-written)"
    return Method(label, "diffrax", "rtol", case.peer_tolerances, runner)


def scipy_method(case: Case, family: str, method: str, route_of) -> Method:
    routes: list[peers.NumpyRoute] = []  # SymPy derives once per scene, when first run

    def runner(value: float) -> Runner:
        if not routes:
            routes.append(route_of(case.peer))
        route = routes[0]
        convert = jax.jit(jax.vmap(lambda y: route.comparable(jnp, y)))

        def finish(output):
            series = np.asarray(convert(jnp.asarray(output)))
            return series[-1], series, len(output) - 1

        run = peers.scipy_run(route, case.t1, method, value)
        return Runner(run, (), False, finish, route.derivation_seconds)

    # Implicit scipy methods at rtol below 1e-8 take minutes here: not swept there.
    tolerances = case.peer_tolerances[: 3 if method in ("LSODA", "Radau") else None]
    label = {
        "scipy": f"scipy {method} (hand-written numpy)",
        "sympy": f"SymPy LagrangesMethod → scipy {method}",
    }[family]
    return Method(label, family, "rtol", tolerances, runner)


def all_methods(case: Case, quick: bool) -> list[Method]:
    methods = [
        lagjax_method(case, name, solver, True, steps)
        for name, (solver, steps) in case.fixed.items()
    ] + [
        lagjax_method(case, name, solver, False, tolerances)
        for name, (solver, tolerances) in case.adaptive.items()
    ]
    for name in ("Dopri8",) if quick else ("Tsit5", "Dopri8"):
        methods.append(diffrax_method(case, name, getattr(diffrax, name)()))
    if not peers.have_scipy():
        print("  scipy is not installed: the scipy and SymPy peers are skipped")
        return methods
    for name in case.scipy_methods:
        methods.append(scipy_method(case, "scipy", name, peers.hand_written_numpy))
    if not peers.have_sympy():
        print("  sympy is not installed: the SymPy route is skipped")
    elif case.peer.sympy_lagrangian is not None:
        methods.append(scipy_method(case, "sympy", "DOP853", peers.sympy_numpy))
    return methods


def reference_state(case: Case) -> tuple[np.ndarray, float]:
    """(final comparable state, its estimated relative accuracy)."""
    if case.exact is not None:
        return case.exact, 0.0
    method = lagjax_method(case, "Dopri8", diffrax.Dopri8(), False, REFERENCE_RTOL)
    finals = []
    for rtol in REFERENCE_RTOL:
        runner = method.runner(rtol)
        finals.append(np.asarray(jax.jit(runner.fn)(*runner.args)[0])[-1])
    return finals[1], diagnostics.final_state_error(finals[0], finals[1])


def case_energy(case: Case) -> Callable[[np.ndarray], np.ndarray]:
    """Energies of comparable states: H or the Jacobi integral (½Σ Iω² for a body)."""
    if case.key == "rigid":
        moments = np.asarray(case.scene.moments)
        return lambda states: 0.5 * np.sum(moments * np.asarray(states)[:, 9:] ** 2, -1)
    q0 = jnp.asarray(case.start()[0])
    system = case.scene.system()
    lag = system if isinstance(system, lj.Lagrangian) else system.to_lagrangian()

    def one(state):
        q, v = state[: q0.size].reshape(q0.shape), state[q0.size :].reshape(q0.shape)
        return lag.energy(q, v, 0.0, case.scene)

    energies = jax.jit(jax.vmap(one))
    return lambda states: np.asarray(energies(jnp.asarray(states)))


def measure_point(case, method, value, reference, energy, timing) -> dict:
    record = dict(
        scene=case.key, method=method.label, family=method.family,
        parameter=method.parameter, value=value, compile_s=math.nan, setup_s=0.0,
        run_s=math.nan, repeats=0, steps=-1, error=math.nan, energy_error=math.nan,
        outcome="ok", reason="",
    )  # fmt: skip
    try:
        runner = method.runner(value)
        measured = diagnostics.time_run(
            runner.fn, *runner.args, jit=runner.jit, warmup=int(runner.jit), **timing
        )
        final, series, steps = runner.finish(measured.output)
        record.update(
            compile_s=measured.compile_seconds, setup_s=runner.setup_seconds,
            run_s=measured.run_seconds, repeats=len(measured.runs), steps=steps,
            error=diagnostics.final_state_error(final, reference),
            energy_error=float(diagnostics.energy_error(energy(series))),
        )  # fmt: skip
    except Exception as error:  # a refused point is a result, not a crash
        record.update(outcome="failed", reason=diagnostics.failure_reason(error))
    if not math.isfinite(record["error"]) and record["outcome"] == "ok":
        record.update(outcome="failed", reason="non-finite final state")
    return record


# fmt: off
# The case table is laid out by hand: one scene, or one sweep, per line.
SOLVERS = {
    "StormerVerlet": lj.StormerVerlet(), "Yoshida4": lj.Yoshida4(), "KahanLi8": lj.KahanLi8(),
    "GaussLegendre(2)": lj.GaussLegendre(stages=2), "GaussLegendre(3)": lj.GaussLegendre(stages=3),
    "RigidBodyVerlet": RigidBodyVerlet(), "RigidBodyYoshida4": RigidBodyYoshida4(),
    "Tsit5": diffrax.Tsit5(), "Dopri8": diffrax.Dopri8(), "Kvaerno5": diffrax.Kvaerno5(),
    "QuaternionProjection(Dopri8)": QuaternionProjection(diffrax.Dopri8()),
}
# Step counts over the whole run, coarse to fine.
SPLITTING = {"StormerVerlet": (2e3, 8e3, 3.2e4, 1.28e5), "Yoshida4": (1e3, 3e3, 1e4, 3e4),
             "KahanLi8": (500, 1e3, 2e3, 4e3)}
IMPLICIT = {"GaussLegendre(2)": (1e3, 2e3, 4e3, 8e3), "GaussLegendre(3)": (500, 1e3, 2e3, 4e3)}
RIGID = {"RigidBodyVerlet": SPLITTING["StormerVerlet"], "RigidBodyYoshida4": SPLITTING["Yoshida4"]}
NON_STIFF = ("Tsit5", "Dopri8")


def build_cases(quick: bool) -> list[Case]:
    """The scenes of the report; quick keeps two of them, with two points a line."""
    tolerances = (1e-5, 1e-8) if quick else (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)

    def case(key, title, scene, t1, fixed, adaptive, peer, **kwargs) -> Case:
        steps = {k: tuple(int(n) for n in v) for k, v in fixed.items()}
        lines = {k: (SOLVERS[k], v[:2] if quick else v) for k, v in steps.items()}
        sweeps = {k: (SOLVERS[k], tolerances[:3] if k == "Kvaerno5" else tolerances) for k in adaptive}
        return Case(key, title, scene, t1, lines, sweeps, peer, tolerances, **kwargs)

    kepler, periods = KeplerCartesian(eccentricity=0.6), 10 if quick else 100
    t1 = periods * float(kepler.period())
    orbit = np.concatenate([np.asarray(x) for x in kepler.orbit_state(jnp.asarray(t1))])
    per_orbit = {"StormerVerlet": (1e3, 4e3, 1.6e4, 6.4e4),
                 "Yoshida4": () if quick else (300, 1e3, 3e3, 1e4),
                 "KahanLi8": () if quick else (200, 400, 800, 1600)}
    kepler_lines = {k: tuple(periods * n for n in v) for k, v in per_orbit.items() if v}
    double = DoublePendulum()
    double_lines = {k: IMPLICIT[k] for k in IMPLICIT if not quick or k == "GaussLegendre(2)"}
    cases = [
        case("kepler", f"Kepler e = 0.6, {periods} periods", kepler, t1, kepler_lines,
             NON_STIFF[: 1 if quick else 2], peers.kepler(kepler), exact=orbit),
        case("double_pendulum", "Double pendulum from (2, 2.5) rad, t = 5 s", double, 5.0,
             double_lines, NON_STIFF[1:] if quick else NON_STIFF, peers.double_pendulum(double)),
    ]
    if quick:
        return cases
    pendulum, stiff = SimplePendulum(), FermiPastaUlamChain(frequency=50.0)
    foucault, body, henon = FoucaultPendulum(), TorqueFreeBody(), HenonHeiles()
    return [
        *cases,
        case("pendulum", "Pendulum at 150°, 10 periods", pendulum, 10 * float(pendulum.period()),
             SPLITTING, NON_STIFF, peers.pendulum(pendulum),
             exact=np.array([float(pendulum.amplitude), 0.0])),
        case("henon_heiles", "Hénon–Heiles, E = 0.13, t = 100", henon, 100.0,
             SPLITTING, NON_STIFF, peers.henon_heiles(henon)),
        case("fpu", "Stiff FPU chain, ω = 50, t = 20", stiff, 20.0,
             {k: SPLITTING[k] for k in ("StormerVerlet", "Yoshida4")}, (*NON_STIFF, "Kvaerno5"),
             peers.fermi_pasta_ulam(stiff), scipy_methods=("DOP853", "LSODA", "Radau")),
        case("foucault", "Foucault pendulum at 45°, t = 100 s", foucault, 100.0,
             IMPLICIT, NON_STIFF, peers.foucault(foucault)),
        case("rigid", "Free asymmetric rigid body, I = (1, 2, 3), t = 20", body, 20.0,
             RIGID, ("QuaternionProjection(Dopri8)",), peers.free_rigid_body(body),
             system=body.rigid_body(), states=rotation_and_angular_velocity,
             initial_state=body.initial_body_state()),
    ]
# fmt: on


def run_case(case: Case, quick: bool, timing: dict) -> tuple[list[dict], float]:
    started = time.perf_counter()
    reference, floor = reference_state(case)
    energy = case_energy(case)
    records = []
    for method in all_methods(case, quick):
        for value in method.values:
            record = measure_point(case, method, value, reference, energy, timing)
            records.append(record)
            failure = f"  FAILED: {record['reason'][:90]}" if record["reason"] else ""
            print(
                f"  {method.label:42s} {method.parameter} {value:<8.2g} run "
                f"{record['run_s']:8.2e} s, compile {record['compile_s']:5.2f} s, "
                f"error {record['error']:7.1e}, energy {record['energy_error']:7.1e}"
                + failure,
                flush=True,
            )
    seconds = time.perf_counter() - started
    print(f"  ({seconds:.0f} s; the reference's relative accuracy {floor:.0e})")
    return records, floor


def _points(records: list[dict]) -> list[diagnostics.WorkPrecisionPoint]:
    return [
        diagnostics.WorkPrecisionPoint(r["method"], r["value"], r["run_s"], r["error"])
        for r in records
        if r["outcome"] == "ok"
    ]


def _described(point: diagnostics.WorkPrecisionPoint | None, records) -> str:
    if point is None:
        return "—"
    kind = next(r["parameter"] for r in records if r["method"] == point.method)
    return f"{point.method} ({kind} {point.setting:.3g}): {point.run_seconds:.2e} s"


def fastest_lines(records: list[dict], floors: dict, titles: dict) -> list[str]:
    """Markdown: per scene and error level, the fastest run, lagjax's and the peers'."""
    lines = [
        "| scene | error ≤ | fastest | fastest lagjax | fastest peer | peer / lagjax |",
        "|---|---|---|---|---|---|",
    ]
    for key, title in titles.items():
        rows = [r for r in records if r["scene"] == key]
        ours = _points([r for r in rows if r["family"] == "lagjax"])
        theirs = _points([r for r in rows if r["family"] != "lagjax"])
        for level in ERROR_LEVELS:
            if level < 10 * floors[key]:
                continue  # finer than the reference can judge
            mine = diagnostics.fastest_within(ours, level)
            peer = diagnostics.fastest_within(theirs, level)
            best = diagnostics.fastest_within([p for p in (mine, peer) if p], level)
            ratio = peer.run_seconds / mine.run_seconds if mine and peer else math.nan
            lines.append(
                f"| {title} | {level:.0e} | {best.method if best else '—'} | "
                f"{_described(mine, rows)} | {_described(peer, rows)} | {ratio:.2g} |"
            )
    return lines


# (lagjax method, peer method) run at the same tolerances: same algorithm or tableau.
TWINS = (
    ("lagjax Tsit5", "diffrax Tsit5 (hand-written)"),
    ("lagjax Dopri8", "diffrax Dopri8 (hand-written)"),
    ("lagjax Dopri8", "scipy DOP853 (hand-written numpy)"),
    ("lagjax Dopri8", "SymPy LagrangesMethod → scipy DOP853"),
)


def twin_lines(records: list[dict]) -> list[str]:
    """Same method, same tolerance: median run-time ratios peer / lagjax."""
    lines = [
        "| scene | lagjax | peer | peer / lagjax run time (median over rtol) |",
        "|---|---|---|---|",
    ]
    for key in dict.fromkeys(r["scene"] for r in records):
        ok = [r for r in records if r["scene"] == key and r["outcome"] == "ok"]
        for ours, theirs in TWINS:
            mine = {r["value"]: r["run_s"] for r in ok if r["method"] == ours}
            peer = {r["value"]: r["run_s"] for r in ok if r["method"] == theirs}
            shared = sorted(set(mine) & set(peer))
            if shared:
                ratio = diagnostics.median_ratio(
                    [peer[v] for v in shared], [mine[v] for v in shared]
                )
                lines.append(f"| {key} | {ours} | {theirs} | {ratio:.2f} |")
    return lines


def write_report(out: Path, records, floors, titles, studies, quick: bool) -> None:
    with open(out / "work_precision.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(records[0]))
        writer.writeheader()
        writer.writerows(records)
    for key, title in titles.items():
        points = _points([r for r in records if r["scene"] == key])
        axes = diagnostics.plot_work_precision(points, title=title)
        axes.figure.tight_layout()
        axes.figure.savefig(out / f"wp_{key}.png", dpi=120)
        plt.close(axes.figure)
    meta = dict(
        mode="quick" if quick else "full",
        date=time.strftime("%Y-%m-%d %H:%M"),
        machine=f"{platform.machine()}, {jax.devices()[0].device_kind}",
        jax=jax.__version__,
    )
    report = dict(meta=meta, reference_floor=floors, work_precision=records)
    report.update(studies.get("data", {}))
    (out / "report.json").write_text(json.dumps(report, indent=1, default=str))
    summary = [
        f"# lagjax work-precision summary ({meta['mode']}, {meta['date']})",
        "",
        "The fastest run reaching each relative final-state error. Peers are the "
        "same equations written by hand (diffrax, scipy) or derived by SymPy; run "
        "times are medians of warm runs, compilation and derivation excluded.",
        "",
        *fastest_lines(records, floors, titles),
        "",
        "## Same method and tolerance: lagjax against its peers",
        "",
        *twin_lines(records),
        "",
        "Relative accuracy of the float64 references (0: exact solution): "
        + ", ".join(f"{k} {v:.0e}" for k, v in floors.items()),
        "",
        *studies.get("markdown", []),
    ]
    (out / "summary.md").write_text("\n".join(summary) + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a CI-sized run (< 60 s)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--skip-scaling", action="store_true")
    options = parser.parse_args(argv)
    options.out.mkdir(parents=True, exist_ok=True)
    quick = options.quick
    timing = (
        dict(repeats=3, max_seconds=0.3) if quick else dict(repeats=5, max_seconds=2.0)
    )
    started = time.perf_counter()
    records, floors, titles = [], {}, {}
    for case in build_cases(quick):
        print(f"== {case.title}", flush=True)
        case_records, floors[case.key] = run_case(case, quick, timing)
        records += case_records
        titles[case.key] = case.title
    studies: dict = {}
    if not options.skip_scaling:
        import scaling

        studies = scaling.run_all(options.out, quick, timing)
    write_report(options.out, records, floors, titles, studies, quick)
    print(f"total {time.perf_counter() - started:.0f} s; results in {options.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
