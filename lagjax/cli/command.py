"""The `lagjax` command: list scenes, run one, and report what it did.

    lagjax scenes
    lagjax run SCENE [--t1 T] [--dt DT] [--solver NAME] [--param k=v ...]
                     [--batch N] [--plot out.png] [--save out.npz] [--backward]
    lagjax bench [--quick]

The command never shows a traceback. Bad arguments — an unknown scene or solver, a
parameter out of its physical range (`--param mass=-1`), a non-finite or hopeless
step (`--dt nan`, `--dt 1e-300`), an output path that cannot be written — are
refused *before* anything is compiled, with exit status 2 and one line
`lagjax: error: …` naming the problem. A run that fails (a singular mass matrix, a
stage solve that does not converge) exits with status 1 and says why. Ctrl-C stops
a run cleanly (status 130): long runs go in chunks, and the states computed up to
the interrupt are still saved when `--save` asked for them.
"""

from __future__ import annotations

import argparse
import logging
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

import jax
import numpy as np

from lagjax import scenes as scene_catalog
from lagjax._core.cpu_loops import enable_fast_cpu_loops
from lagjax._integrate.solver_choice import default_solver
from lagjax.cli.arguments import (
    SOLVERS,
    build_scene,
    check_distinct_outputs,
    check_output,
    format_values,
    run_options,
)
from lagjax.cli.run import (
    Outcome,
    UsageError,
    check_scales,
    energy_report,
    first_line,
    run_scene,
)
from lagjax.cli.sweep import add_sweep_command
from lagjax.solvers.implicit import (
    AbstractGaussLegendre,
    stage_failure_message,
)

INTERRUPTED = 130  # the shell's status for a run stopped by SIGINT


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


# -- reporting ---------------------------------------------------------------------


def _first_of_batch(trajectory, batch: int | None):
    if batch is None:
        return trajectory
    return jax.tree_util.tree_map(lambda x: x[0], trajectory)


def _summary(scene, name: str, outcome: Outcome, batch: int | None) -> list[str]:
    first = _first_of_batch(outcome.trajectory, batch)
    ts = np.asarray(first.ts)
    lines = [
        f"scene     {name}: {first_line((type(scene).__doc__ or '').strip())}",
        f"solver    {first.stats['solver']}, {outcome.steps} steps"
        + ("" if batch is None else f", batch of {batch}")
        + (f", backward from t = 0 to {ts[-1]:g}" if ts[-1] < ts[0] else ""),
        f"time      run {outcome.run_time:.3f} s (excluding compile), "
        f"compile {outcome.compile_time:.2f} s",
        energy_report(first).line(),
    ]
    try:
        checks = scene.checks(first)
    except ValueError as refusal:  # the run is too short or too coarse to judge
        lines.append(f"check     not judged: {refusal}")
        checks = {}
    for check, (measured, expected) in checks.items():
        measured, expected = np.asarray(measured), np.asarray(expected)
        # One scale for the whole quantity: components that are zero in the closed
        # form (a vector's y-part, say) must not blow the relative error up.
        scale = max(float(np.max(np.abs(expected))), 1e-300)
        error = float(np.max(np.abs(measured - expected))) / scale
        if measured.size <= 3:
            shown = (
                f"{format_values(measured)} vs closed form {format_values(expected)}"
            )
        else:
            shown = f"{measured.size} values along the run vs closed form"
        lines.append(f"check     {check}: {shown} (rel. error {error:.1e})")
    return lines


def _save(path: str, trajectory) -> None:
    """Write the run to exactly `path` (np.savez would append `.npz` to a name)."""
    q_leaves = jax.tree_util.tree_leaves(trajectory.q)
    second = jax.tree_util.tree_leaves(trajectory.ys[1])
    arrays = {
        "ts": np.asarray(trajectory.ts),
        "energy": np.asarray(trajectory.energy()),
    }
    arrays.update({f"q{i}": np.asarray(x) for i, x in enumerate(q_leaves)})
    label = "p" if trajectory.is_hamiltonian else "qdot"
    arrays.update({f"{label}{i}": np.asarray(x) for i, x in enumerate(second)})
    with open(path, "wb") as file:
        np.savez(file, **arrays)  # pyright: ignore[reportArgumentType]


# -- commands ----------------------------------------------------------------------


def _command_run(args) -> int:
    scene = build_scene(args.scene, args.param)
    t1, dt, solver = run_options(scene, args)
    check_output(args.plot, "--plot")
    check_output(args.save, "--save")
    check_distinct_outputs(args.save, args.plot)
    check_scales(scene)
    try:
        outcome = run_scene(scene, t1, dt, solver, args.batch)
    except (UsageError, KeyboardInterrupt):
        raise
    except Exception as error:
        raise RunFailed(_reason(error, scene, solver, dt)) from None
    first = _first_of_batch(outcome.trajectory, args.batch)
    if outcome.interrupted:
        reached = float(np.asarray(first.ts)[-1])
        saved = ""
        if args.save:
            _save(args.save, first)
            saved = f"; the {np.size(first.ts)} states up to there are in {args.save}"
        print(
            f"lagjax: interrupted at t = {reached:.6g} of {t1:g}{saved}",
            file=sys.stderr,
        )
        return INTERRUPTED
    for line in _summary(scene, args.scene, outcome, args.batch):
        print(line)
    if args.save:  # data first: a failing plot must not lose the run
        _save(args.save, first)
        print(f"data      {args.save}")
    if args.plot:
        # matplotlib is the optional `plot` extra: imported only when a plot is asked
        from lagjax.cli.plot import plot_run

        plot_run(args.plot, args.scene, scene, first)
        print(f"plot      {args.plot}")
    return 0


def _command_scenes(_args) -> int:
    print(scene_catalog.describe())
    return 0


def _command_bench(args) -> int:
    """Run the work-precision benchmark of a clone of the repository."""
    import subprocess

    root = Path(__file__).resolve().parent.parent.parent
    if not (root / "benchmarks" / "work_precision.py").exists():
        raise UsageError(
            "`lagjax bench` runs the benchmarks/ folder of a clone of the "
            "repository, which an installed wheel does not contain: clone the "
            "repository and run `python -m benchmarks.work_precision` in it"
        )
    command = [sys.executable, "-m", "benchmarks.work_precision"]
    return subprocess.call(command + (["--quick"] if args.quick else []), cwd=root)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="lagjax", description="Classical mechanics in JAX.")
    commands = parser.add_subparsers(
        dest="command", required=True, parser_class=_Parser
    )
    commands.add_parser("scenes", help="list the scenes").set_defaults(
        handler=_command_scenes
    )
    run = commands.add_parser("run", help="integrate a scene and report")
    run.add_argument("scene")
    run.add_argument("--t1", type=float, default=None, help="end time [s]")
    run.add_argument("--dt", type=float, default=None, help="fixed step [s]")
    run.add_argument("--solver", default=None, help=f"one of: {', '.join(SOLVERS)}")
    run.add_argument(
        "--param",
        action="append",
        default=[],
        help="scene parameter NAME=VALUE (a vector: NAME=V1,V2,V3)",
    )
    run.add_argument(
        "--batch", type=int, default=None, help="run N perturbed copies (vmap)"
    )
    run.add_argument(
        "--plot", default=None, help="write a figure (PNG, PDF, SVG) of the run"
    )
    run.add_argument("--save", default=None, help="write the trajectory as .npz")
    run.add_argument("--backward", action="store_true", help="integrate towards t1 < 0")
    run.set_defaults(handler=_command_run)
    bench = commands.add_parser(
        "bench", help="run the benchmark report (needs a clone)"
    )
    bench.add_argument("--quick", action="store_true")
    bench.set_defaults(handler=_command_bench)
    add_sweep_command(commands, SOLVERS)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command; return its exit status (0 done, 1 run failed, 2 bad
    arguments, 130 interrupted). Never raises, never prints a traceback."""
    # JAX logs a traceback of its own when a run-time check fires inside a compiled
    # run; the command reports the reason in one line instead.
    logging.getLogger("jax._src.callback").setLevel(logging.CRITICAL)
    # The command is a program of its own: float64 throughout, and whole loop
    # bodies as one kernel on CPU (both are the caller's choice in a library call).
    enable_fast_cpu_loops()
    jax.config.update("jax_enable_x64", True)
    try:
        args = _parser().parse_args(argv)
        return args.handler(args)
    except SystemExit as done:  # --help
        return done.code if isinstance(done.code, int) else 0
    except UsageError as error:
        _error(str(error))
        return 2
    except KeyboardInterrupt:
        _error("interrupted before any state was computed; nothing saved")
        return INTERRUPTED
    except RunFailed as error:
        _error(f"run failed: {error}")
        return 1
    except Exception as error:  # anything else: still one line, never a traceback
        _error(f"run failed: {_reason(error)}")
        return 1


def _error(message: str) -> None:
    print(f"lagjax: error: {first_line(message)}", file=sys.stderr)


class RunFailed(Exception):
    """A run that started and failed: reported in one line, exit status 1."""


def _reason(error: Exception, scene=None, solver=None, dt=None) -> str:
    """The line of an (often long, JIT-wrapped) error message that says what failed;
    for a failed implicit stage solve, what to change (`stage_failure_message`)."""
    return _command_remedies(_library_reason(error, scene, solver, dt))


def _command_remedies(text: str) -> str:
    """`text` without the sentences that name library-only remedies (a command's
    user cannot pass throw=False or read an exception's .trajectory)."""
    sentences = re.split(r"(?<=\.)\s+", text)
    kept = [s for s in sentences if "throw=False" not in s and ".trajectory" not in s]
    return " ".join(kept) if kept else text


def _library_reason(error: Exception, scene=None, solver=None, dt=None) -> str:
    text = str(error)
    if scene is not None and ("nonlinear solver" in text or "Nonfinite" in text):
        chosen = solver if solver is not None else default_solver(scene, dt)
        if isinstance(chosen, AbstractGaussLegendre):
            return stage_failure_message(chosen)
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    keywords = (
        "singular",
        "non-finite",
        "Nonfinite",
        "maximum number of steps",
        "nonlinear solver",
        "diverge",
    )
    # equinox's run-time errors carry the reason after the class name, below a
    # copy of the stack; skip the stack's file and code lines.
    for line in lines:
        if "RuntimeError: " in line:
            return line.split("RuntimeError: ", 1)[1]
    for line in lines:
        if any(word in line for word in keywords) and not line.startswith("File "):
            return line
    return f"{type(error).__name__}: {lines[0] if lines else ''}"


if __name__ == "__main__":
    sys.exit(main())
