"""The `lagjax` command: list scenes, run one, and report what it did.

    lagjax scenes
    lagjax run SCENE [--t1 T] [--dt DT] [--solver NAME] [--param k=v ...]
                     [--batch N] [--plot out.png] [--save out.npz] [--backward]
    lagjax bench [--quick]

Bad arguments exit with status 2 and one line naming the problem; a failed run
(e.g. a singular mass matrix) exits with status 1 and says why.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from jax.flatten_util import ravel_pytree  # noqa: E402

from . import scenes as scene_catalog  # noqa: E402
from .simulate import simulate  # noqa: E402
from .solvers.implicit import GaussLegendre, ImplicitMidpoint  # noqa: E402
from .solvers.rattle import Rattle  # noqa: E402
from .solvers.lie_poisson import RigidBodyVerlet, RigidBodyYoshida4  # noqa: E402
from .solvers.splitting import (  # noqa: E402
    BlanesMoan4,
    KahanLi8,
    SofSpa10,
    StormerVerlet,
    Yoshida4,
    Yoshida6,
)
from .solvers.variational import VariationalMidpoint  # noqa: E402

SOLVERS: dict[str, Callable[[], diffrax.AbstractSolver]] = {
    "StormerVerlet": StormerVerlet,
    "Yoshida4": Yoshida4,
    "Yoshida6": Yoshida6,
    "KahanLi8": KahanLi8,
    "SofSpa10": SofSpa10,
    "BlanesMoan4": BlanesMoan4,
    "ImplicitMidpoint": ImplicitMidpoint,
    "GaussLegendre1": lambda: GaussLegendre(stages=1),
    "GaussLegendre2": lambda: GaussLegendre(stages=2),
    "GaussLegendre3": lambda: GaussLegendre(stages=3),
    "VariationalMidpoint": VariationalMidpoint,
    "Tsit5": diffrax.Tsit5,
    "Dopri5": diffrax.Dopri5,
    "Dopri8": diffrax.Dopri8,
    "Kvaerno5": diffrax.Kvaerno5,
    "RigidBodyVerlet": RigidBodyVerlet,
    "RigidBodyYoshida4": RigidBodyYoshida4,
    "Rattle": Rattle,
}
SAVED_POINTS = 401
PROGRESS_STEPS = 200_000


class UsageError(Exception):
    """A bad command-line argument: reported in one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def _parse_param(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise UsageError(f"--param expects NAME=VALUE, got {text!r}")
    try:
        return name, float(value)
    except ValueError:
        raise UsageError(f"--param {name}: {value!r} is not a number") from None


def _build_scene(name: str, params: Sequence[str]):
    catalog = scene_catalog.catalog()
    if name not in catalog:
        raise UsageError(f"unknown scene {name!r}; `lagjax scenes` lists them")
    scene_class = catalog[name]
    values = dict(_parse_param(text) for text in params)
    try:
        return scene_class(**values)
    except TypeError as error:
        raise UsageError(f"scene {name}: {error}") from None


def _options(scene, args) -> tuple[float, float | None, Any]:
    t1 = scene.default_t1 if args.t1 is None else args.t1
    dt = scene.default_dt if args.dt is None else args.dt
    if dt is not None and dt <= 0:
        raise UsageError(
            f"--dt must be positive, got {dt} (use --backward to run back)"
        )
    if t1 < 0 and not args.backward:
        raise UsageError(
            f"--t1 {t1} is before t0 = 0; pass --backward to run backwards"
        )
    if args.backward:
        t1, dt = -abs(t1), None if dt is None else -abs(dt)
    if args.solver is not None and args.solver not in SOLVERS:
        raise UsageError(
            f"unknown solver {args.solver!r}; choose from {', '.join(SOLVERS)}"
        )
    solver = None if args.solver is None else SOLVERS[args.solver]()
    if args.batch is not None and args.batch < 1:
        raise UsageError(f"--batch must be at least 1, got {args.batch}")
    return t1, dt, solver


def _perturbed_batch(state, batch: int):
    """`batch` copies of a state, each scaled by 1 + 1e-3·(k − batch/2)/batch."""
    factors = 1.0 + 1e-3 * (jnp.arange(batch) - batch / 2) / batch

    def spread(leaf):
        leaf = jnp.asarray(leaf)
        return factors.reshape((batch,) + (1,) * leaf.ndim) * leaf

    return jax.tree_util.tree_map(spread, state)


def _save_times(t1: float, dt: float | None) -> jax.Array:
    """About SAVED_POINTS times; on the step grid for fixed steps, so the saved
    states are the solver's own, not interpolated between steps."""
    if dt is None:
        return jnp.linspace(0.0, t1, SAVED_POINTS)
    steps = int(np.floor(abs(t1 / dt) + 1e-9))
    stride = max(1, steps // (SAVED_POINTS - 1))
    grid = np.arange(0, steps + 1, stride) * dt
    return jnp.asarray(
        np.unique(np.append(grid, t1)) if t1 > 0 else np.append(grid, t1)
    )


def _run(scene, t1: float, dt: float | None, solver, batch: int | None):
    ts = _save_times(t1, dt)
    steps = abs(t1 / dt) if dt else 0
    kwargs: dict[str, Any] = dict(
        t1=t1, dt=dt, solver=solver, ts=ts, progress=steps > PROGRESS_STEPS
    )
    if dt is not None:
        kwargs["max_steps"] = int(steps) + 2

    def one(state):
        return simulate(scene, state, **kwargs)

    state = scene.initial_state()
    function = one if batch is None else jax.vmap(one)
    inputs = state if batch is None else _perturbed_batch(state, batch)
    start = time.perf_counter()
    compiled = jax.jit(function).lower(inputs).compile()
    compile_time = time.perf_counter() - start
    start = time.perf_counter()
    trajectory = jax.block_until_ready(compiled(inputs))
    return trajectory, compile_time, time.perf_counter() - start


def _summary(scene, name, trajectory, compile_time, run_time, batch) -> list[str]:
    first = (
        trajectory
        if batch is None
        else jax.tree_util.tree_map(lambda x: x[0], trajectory)
    )
    energy = np.asarray(first.energy())
    scale = max(abs(energy[0]), 1e-300)
    lines = [
        f"scene     {name}: {(type(scene).__doc__ or '').strip().splitlines()[0]}",
        f"solver    {first.stats['solver']}, {int(first.stats['num_steps'])} steps"
        + ("" if batch is None else f", batch of {batch}"),
        f"time      run {run_time:.3f} s (excluding compile), compile {compile_time:.2f} s",
        f"energy    max relative error {np.max(np.abs(energy - energy[0])) / scale:.2e}",
    ]
    for check, (measured, expected) in scene.checks(first).items():
        measured, expected = np.asarray(measured), np.asarray(expected)
        # One scale for the whole quantity: components that are zero in the closed
        # form (a vector's y-part, say) must not blow the relative error up.
        scale = max(float(np.max(np.abs(expected))), 1e-300)
        error = float(np.max(np.abs(measured - expected))) / scale
        if measured.size <= 3:
            shown = f"{_format(measured)} vs closed form {_format(expected)}"
        else:
            shown = f"{measured.size} values along the run vs closed form"
        lines.append(f"check     {check}: {shown} (rel. error {error:.1e})")
    return lines


def _format(values: np.ndarray) -> str:
    flat = [f"{float(x):.10g}" for x in np.ravel(values)]
    return flat[0] if len(flat) == 1 else "(" + ", ".join(flat) + ")"


def _plot(path: str, name: str, trajectory) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ts = np.asarray(trajectory.ts)
    flat_q = np.asarray(jax.vmap(lambda q: ravel_pytree(q)[0])(trajectory.q))
    energy = np.asarray(trajectory.energy())
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for index in range(flat_q.shape[1]):
        top.plot(ts, flat_q[:, index], label=f"q[{index}]")
    if flat_q.shape[1] <= 8:
        top.legend(loc="upper right", fontsize="small")
    top.set_ylabel("generalized coordinates q")
    top.set_title(f"lagjax run {name}")
    bottom.semilogy(
        ts[1:], np.abs(energy[1:] - energy[0]) / max(abs(energy[0]), 1e-300) + 1e-17
    )
    bottom.set_xlabel("t [s]")
    bottom.set_ylabel("relative energy error")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def _save(path: str, trajectory) -> None:
    q_leaves = jax.tree_util.tree_leaves(trajectory.q)
    second = jax.tree_util.tree_leaves(trajectory.ys[1])
    arrays = {
        "ts": np.asarray(trajectory.ts),
        "energy": np.asarray(trajectory.energy()),
    }
    arrays.update({f"q{i}": np.asarray(x) for i, x in enumerate(q_leaves)})
    label = "p" if trajectory.is_hamiltonian else "qdot"
    arrays.update({f"{label}{i}": np.asarray(x) for i, x in enumerate(second)})
    np.savez(path, **arrays)  # pyright: ignore[reportArgumentType]


def _command_run(args) -> int:
    scene = _build_scene(args.scene, args.param)
    t1, dt, solver = _options(scene, args)
    trajectory, compile_time, run_time = _run(scene, t1, dt, solver, args.batch)
    for line in _summary(
        scene, args.scene, trajectory, compile_time, run_time, args.batch
    ):
        print(line)
    first = (
        trajectory
        if args.batch is None
        else jax.tree_util.tree_map(lambda x: x[0], trajectory)
    )
    if args.plot:
        _plot(args.plot, args.scene, first)
        print(f"plot      {args.plot}")
    if args.save:
        _save(args.save, first)
        print(f"data      {args.save}")
    return 0


def _command_scenes(_args) -> int:
    for name, scene_class in scene_catalog.catalog().items():
        print(f"{name:24s} {(scene_class.__doc__ or '').strip().splitlines()[0]}")
    return 0


def _command_bench(args) -> int:
    import runpy
    from pathlib import Path

    script = Path(__file__).resolve().parent.parent / "benchmarks" / "work_precision.py"
    if not script.exists():
        raise UsageError("the benchmarks/ folder is not next to this installation")
    sys.argv = [str(script)] + (["--quick"] if args.quick else [])
    runpy.run_path(str(script), run_name="__main__")
    return 0


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
        "--param", action="append", default=[], help="scene parameter NAME=VALUE"
    )
    run.add_argument(
        "--batch", type=int, default=None, help="run N perturbed copies (vmap)"
    )
    run.add_argument(
        "--plot", default=None, help="write a PNG of q(t) and the energy error"
    )
    run.add_argument("--save", default=None, help="write the trajectory as .npz")
    run.add_argument("--backward", action="store_true", help="integrate towards t1 < 0")
    run.set_defaults(handler=_command_run)
    bench = commands.add_parser("bench", help="run the benchmark report")
    bench.add_argument("--quick", action="store_true")
    bench.set_defaults(handler=_command_bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    # JAX logs a traceback of its own when a run-time check fires inside a compiled
    # run; the command reports the reason in one line instead.
    logging.getLogger("jax._src.callback").setLevel(logging.CRITICAL)
    try:
        args = _parser().parse_args(argv)
        return args.handler(args)
    except UsageError as error:
        print(f"lagjax: error: {error}", file=sys.stderr)
        return 2
    except Exception as error:  # a run that failed: say why in one line
        print(f"lagjax: run failed: {_reason(error)}", file=sys.stderr)
        return 1


def _reason(error: Exception) -> str:
    """The line of an (often long, JIT-wrapped) error message that says what failed."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    keywords = (
        "singular",
        "non-finite",
        "Nonfinite",
        "maximum number of steps",
        "nonlinear solver",
    )
    for line in lines:
        if any(word in line for word in keywords):
            return line
    return f"{type(error).__name__}: {lines[0] if lines else ''}"


if __name__ == "__main__":
    sys.exit(main())
