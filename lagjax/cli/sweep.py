"""`lagjax sweep`: a scene over a grid of parameters and starts, streamed to disk.

    lagjax sweep SCENE --out DIR [--param NAME=VALUES ...] [--q0 [COORD=]VALUES ...]
                 [--qdot0 | --p0 [COORD=]VALUES ...] [--zip] [--t1 T] [--dt DT]
                 [--solver NAME] [--saves N] [--measure megno] [--chunk-size N]
                 [--quiet]
                 [--distributed | --coordinator HOST:PORT --processes P --process-id K]

One member per point of the grid (`lagjax.cli.sweep_grid` says how VALUES and the
grid are written); every member is one `simulate` run of the scene from t = 0 to t1
— or, with `--measure megno`, its MEGNO ⟨Y⟩(t1) (`lj.megno`: a MEGNO map, field
`value`) — and `lj.sweep_to_disk` streams the results to DIR in chunks (`.npy`
files and an `index.json` that also records the grid: `attributes`). Rerunning the same command
resumes after the chunks already on disk. Progress (members done, rate, time left)
goes to stderr, one line per chunk; the summary to stdout.

Bad inputs — an unknown scene, parameter, coordinate or solver, a value the scene
refuses, a range that is not one, axes of different lengths under `--zip`, a
directory that holds another sweep or cannot be written — are refused before
anything is compiled: one line `lagjax: error: …` and exit status 2. Members that
fail are marked in DIR (their `RESULTS` code) and counted in the summary; the
command still exits 0. Ctrl-C keeps the finished chunks (exit status 130).

Several processes (one per host or GPU) run the same command with `--distributed`
(SLURM, Open MPI: detected by `jax.distributed.initialize()`) or with an explicit
coordinator; each writes its chunks into DIR, which all must see.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

from lagjax import scenes as scene_catalog
from lagjax._integrate.checks.inputs import check_times
from lagjax._integrate.simulate import simulate
from lagjax._integrate.solver_choice import default_solver
from lagjax._sweep.progress import SweepProgress
from lagjax._sweep.reader import open_sweep
from lagjax._sweep.to_disk import DEFAULT_CHUNK_SIZE, sweep_to_disk
from lagjax.cli.run import UsageError, _save_times, first_line
from lagjax.cli.sweep_grid import (
    Setting,
    check_parameters,
    member_scenes_and_starts,
    member_values,
    parameter_setting,
    split_parameters,
    state_setting,
)
from lagjax.phase_space.indicators import megno

INTERRUPTED = 130
# What `--measure` may ask of a member besides its trajectory.
MEASURES = {"megno": megno}


def add_sweep_command(commands: Any, solvers: dict[str, Callable[[], Any]]) -> None:
    """Register `lagjax sweep` on the command's subparsers."""
    sweep = commands.add_parser(
        "sweep", help="run a scene over a grid of parameters and starts, to disk"
    )
    sweep.add_argument("scene")
    sweep.add_argument("--out", required=True, help="directory for the results")
    for flag, meaning in (
        ("param", "scene parameter NAME=VALUES (NAME[i]=VALUES: entry i)"),
        ("q0", "starting coordinate [COORD=]VALUES"),
        ("qdot0", "starting velocity [COORD=]VALUES (scenes started from q, q̇)"),
        ("p0", "starting momentum [COORD=]VALUES (scenes started from q, p)"),
    ):
        sweep.add_argument(
            f"--{flag}",
            dest="settings",
            action="append",
            default=[],
            type=lambda text, flag=flag: (flag, text),
            metavar="SPEC",
            help=f"{meaning}; VALUES: 1.5 | 0.5,1,2 | 0.5:2:64 | 1e-3:1:50:log",
        )
    sweep.add_argument(
        "--zip", action="store_true", help="pair the axes instead of a grid"
    )
    sweep.add_argument("--t1", type=float, default=None, help="end time [s]")
    sweep.add_argument("--dt", type=float, default=None, help="fixed step [s]")
    sweep.add_argument("--solver", default=None, help=f"one of: {', '.join(solvers)}")
    sweep.add_argument(
        "--saves", type=int, default=None, help="save N times from 0 to t1"
    )
    sweep.add_argument(
        "--measure",
        default=None,
        help=f"store a measure instead of the trajectory: {', '.join(MEASURES)}",
    )
    sweep.add_argument(
        "--chunk-size", type=int, default=DEFAULT_CHUNK_SIZE, help="members per file"
    )
    sweep.add_argument("--quiet", action="store_true", help="no progress lines")
    sweep.add_argument(
        "--distributed", action="store_true", help="join JAX's distributed runtime"
    )
    sweep.add_argument("--coordinator", default=None, help="HOST:PORT of process 0")
    sweep.add_argument("--processes", type=int, default=None)
    sweep.add_argument("--process-id", type=int, default=None)
    sweep.set_defaults(handler=command_sweep, solvers=solvers)


# -- checks ------------------------------------------------------------------------


def _join_processes(args) -> None:
    """Start JAX's distributed runtime first, before anything touches JAX."""
    explicit = (args.coordinator, args.processes, args.process_id)
    if all(value is None for value in explicit) and not args.distributed:
        return
    if any(value is None for value in explicit) and not all(
        value is None for value in explicit
    ):
        raise UsageError(
            "--coordinator, --processes and --process-id go together (or use "
            "--distributed alone under SLURM or Open MPI)"
        )
    try:
        jax.distributed.initialize(
            args.coordinator, num_processes=args.processes, process_id=args.process_id
        )
    except (RuntimeError, ValueError) as error:
        raise UsageError(
            f"JAX's distributed runtime did not start ({first_line(error)}): run "
            "under SLURM or Open MPI, or give --coordinator, --processes and "
            "--process-id"
        ) from None


def _times(scene, args) -> tuple[float, float, Any]:
    t1 = scene.default_t1 if args.t1 is None else args.t1
    dt = scene.default_dt if args.dt is None else args.dt
    for flag, value in (("--t1", t1), ("--dt", dt)):
        if not math.isfinite(value) or value <= 0:
            raise UsageError(f"{flag} must be a positive finite number, got {value}")
    try:
        check_times(0.0, t1, dt)
    except ValueError as error:
        raise UsageError(str(error).replace("dt = ", "--dt ", 1)) from None
    if args.saves is None:
        return t1, dt, None
    if args.saves < 2:
        raise UsageError(
            f"--saves must be at least 2 (the start and t1), got {args.saves}; "
            "leave it out to keep the final state only"
        )
    return t1, dt, _save_times(t1, dt, t1 / (args.saves - 1), args.saves)


def _settings(args, scene_class, default) -> list[Setting]:
    settings = []
    for flag, text in args.settings:
        if flag == "param":
            settings.append(parameter_setting(text, args.scene, default))
        else:
            settings.append(state_setting(flag, text, args.scene, default))
    seen = {}
    for setting in settings:
        target = (setting.flag, setting.key, setting.entry)
        if target in seen:
            raise UsageError(
                f"--{setting.flag} {setting.name} is given twice ({seen[target]!r}, "
                f"{setting.text!r}): give each target once"
            )
        seen[target] = setting.text
    return settings


# -- the sweep ---------------------------------------------------------------------


def _members(args, scene_class, default):
    """(system, y0s, args_batch, grid description) for the command's settings."""
    settings = _settings(args, scene_class, default)
    values, shape = member_values(settings, args.zip)
    members = math.prod(shape)
    fixed, batched = split_parameters(settings, values, default, members)
    check_parameters(scene_class, fixed, batched)
    scenes, y0s = member_scenes_and_starts(
        scene_class, fixed, batched, settings, values, members
    )
    grid = {
        "scene": args.scene,
        "layout": "zip" if args.zip else "grid",
        "shape": list(shape),
        "axes": [
            {"flag": f"--{s.flag}", "target": s.name, "values": s.values.tolist()}
            for s in settings
            if s.is_axis
        ],
        "fixed": {
            f"--{s.flag} {s.name}": s.values.tolist() for s in settings if not s.is_axis
        },
    }
    return scene_class(**fixed), y0s, scenes, grid


def _library_refusal(error: Exception) -> UsageError:
    """A refusal of `sweep_to_disk`, in the command's words."""
    message = first_line(error)
    for api, flag in (("out_dir ", "--out "), ("chunk_size=", "--chunk-size ")):
        message = message.replace(api, flag)
    return UsageError(message)


def command_sweep(args) -> int:
    _join_processes(args)
    catalog = scene_catalog.catalog()
    if args.scene not in catalog:
        raise UsageError(f"unknown scene {args.scene!r}; `lagjax scenes` lists them")
    scene_class = catalog[args.scene]
    default = scene_class()
    t1, dt, ts = _times(default, args)
    if args.solver is not None and args.solver not in args.solvers:
        raise UsageError(
            f"unknown solver {args.solver!r}; choose from {', '.join(args.solvers)}"
        )
    if args.chunk_size < 1:
        raise UsageError(f"--chunk-size must be at least 1, got {args.chunk_size}")
    measure = _measure(args)
    solver = None if args.solver is None else args.solvers[args.solver]()
    system, y0s, scenes, grid = _members(args, scene_class, default)
    reports: list[SweepProgress] = []

    def progress(report: SweepProgress) -> None:
        reports.append(report)
        if not args.quiet:
            print(report.line(), file=sys.stderr, flush=True)

    options = dict(t1=t1, dt=dt, solver=solver)
    if measure is simulate:
        options["ts"] = ts
    start = time.perf_counter()
    try:
        store = sweep_to_disk(
            system, y0s, scenes, out_dir=args.out, chunk_size=args.chunk_size,
            progress=progress, attributes={"lagjax sweep": grid}, measure=measure,
            **options,
        )  # fmt: skip
    except (ValueError, TypeError) as error:
        if reports:  # a chunk was written: not a refusal, a failure
            raise
        raise _library_refusal(error) from None
    except KeyboardInterrupt:
        return _interrupted(Path(args.out))
    seconds = time.perf_counter() - start
    if jax.process_index() == 0:
        solver_name = type(solver or default_solver(system, dt)).__name__
        for line in _summary(store, grid, solver_name, t1, dt, reports, seconds):
            print(line)
    return 0


def _measure(args) -> Any:
    """The function run per member: `simulate`, or the one `--measure` names."""
    if args.measure is None:
        return simulate
    if args.measure not in MEASURES:
        raise UsageError(
            f"unknown measure {args.measure!r}; choose from {', '.join(MEASURES)}"
        )
    if args.saves is not None:
        raise UsageError(
            f"--saves keeps states along the trajectory, which --measure "
            f"{args.measure} does not store: leave one of them out"
        )
    return MEASURES[args.measure]


def _interrupted(out: Path) -> int:
    try:
        store = open_sweep(out)
    except ValueError:
        done = "nothing was written"
    else:
        members = sum(c["stop"] - c["start"] for c in store.index["chunks"])
        done = f"{members} of {store.index['members']} members are in {out}"
    print(
        f"lagjax: interrupted; {done}: run the same command again to resume",
        file=sys.stderr,
    )
    return INTERRUPTED


def _summary(store, grid, solver_name, t1, dt, reports, seconds) -> list[str]:
    index = store.index
    total = index["members"]
    done = sum(c["stop"] - c["start"] for c in index["chunks"])
    this_call = reports[-1].members_this_call if reports else 0
    axes = " × ".join(
        f"{axis['flag']} {axis['target']} ({len(axis['values'])})"
        for axis in grid["axes"]
    )
    lines = [
        f"scene     {grid['scene']}",
        f"members   {total}" + (f" = {axes}" if axes else "")
        + (" (zipped)" if grid["layout"] == "zip" else ""),
        f"solver    {solver_name}, t1 = {t1:g}, dt = {dt:g}"
        + (f"; measure {index['parameters']['measure']} in field "
           f"{', '.join(f for f in store.fields if f != 'finite')}"
           if "measure" in index["parameters"] else ""),
        f"chunks    {len(index['chunks'])} of {index['chunk_count']} on disk "
        f"({done - this_call} members resumed, {this_call} run now)",
        f"time      {seconds:.2f} s"
        + (f", {this_call / seconds:.4g} members/s (compile included)"
           if this_call else ""),
    ]  # fmt: skip
    lines += _failures(store, index)
    lines.append(f"output    {store.path} (lj.open_sweep, or numpy and index.json)")
    return lines


def _failures(store, index) -> list[str]:
    failed = sum(c["failed"] for c in index["chunks"])
    if not failed:
        return ["failed    0 members"]
    members = np.flatnonzero(store.failed())
    if "result" not in store.fields:  # a measure: no RESULTS code, a NaN or inf
        reason = "its measured value is not finite"
    else:
        code = str(int(store.array("result")[members[0]]))
        reason = index["result_messages"].get(code, "")
        if code == "0":
            reason = "the state stopped being finite"
    return [
        f"failed    {failed} members (first: member {members[0]}, {first_line(reason)})"
    ]
