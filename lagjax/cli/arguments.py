"""The `lagjax` command's arguments: scenes, parameters, times, solvers and output
paths, checked before anything is compiled.

Every refusal is a `UsageError` naming the flag and the problem (the command
prints it as one line and exits with status 2): an unknown scene or solver, a
parameter of the wrong shape or out of its physical range, a non-finite or
hopeless step, an output path that cannot be written or a figure format
matplotlib does not know.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import diffrax
import numpy as np

from lagjax import scenes as scene_catalog
from lagjax._integrate.checks.inputs import check_times
from lagjax.cli.run import UsageError, first_line
from lagjax.solvers.implicit import GaussLegendre, ImplicitMidpoint
from lagjax.solvers.lie_poisson import RigidBodyVerlet, RigidBodyYoshida4
from lagjax.solvers.rattle import Rattle
from lagjax.solvers.splitting import (
    BlanesMoan4,
    BlanesMoan6,
    BlanesMoanNystrom6,
    KahanLi8,
    SofSpa10,
    StormerVerlet,
    Yoshida4,
    Yoshida6,
)
from lagjax.solvers.variational import VariationalMidpoint

SOLVERS: dict[str, Callable[[], diffrax.AbstractSolver]] = {
    "StormerVerlet": StormerVerlet,
    "Yoshida4": Yoshida4,
    "Yoshida6": Yoshida6,
    "KahanLi8": KahanLi8,
    "SofSpa10": SofSpa10,
    "BlanesMoan4": BlanesMoan4,
    "BlanesMoan6": BlanesMoan6,
    "BlanesMoanNystrom6": BlanesMoanNystrom6,
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


def parse_param(text: str) -> tuple[str, np.ndarray]:
    """`NAME=VALUE` or `NAME=V1,V2,V3` (a vector parameter), finite numbers only."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise UsageError(f"--param expects NAME=VALUE, got {text!r}")
    try:
        numbers = [float(part) for part in value.split(",")]
    except ValueError:
        raise UsageError(f"--param {name}: {value!r} is not a number") from None
    if not all(math.isfinite(x) for x in numbers):
        raise UsageError(f"--param {name}={value}: parameters must be finite numbers")
    return name, np.asarray(numbers if len(numbers) > 1 else numbers[0])


def build_scene(name: str, params: Sequence[str]):
    catalog = scene_catalog.catalog()
    if name not in catalog:
        raise UsageError(f"unknown scene {name!r}; `lagjax scenes` lists them")
    scene_class = catalog[name]
    pairs = [parse_param(text) for text in params]
    values = dict(pairs)
    if len(values) < len(pairs):
        twice = next(k for k in values if sum(key == k for key, _ in pairs) > 1)
        raise UsageError(
            f"--param {twice} is given more than once; give each parameter once"
        )
    default = scene_class()
    fields = {field.name for field in dataclasses.fields(scene_class)}
    for key, value in values.items():
        if key not in fields:
            known = ", ".join(sorted(fields)) or "none"
            raise UsageError(
                f"scene {name} has no parameter {key!r} (unexpected keyword); its "
                f"parameters: {known}"
            )
        expected = np.shape(getattr(default, key))
        if value.shape != expected:
            raise UsageError(
                f"--param {key}: scene {name} needs {_shape_words(expected)}, got "
                f"{_shape_words(value.shape)}"
                + (f"; e.g. {key}=1,2,3" if expected == (3,) else "")
            )
    try:
        return scene_class(**values)
    except (ValueError, TypeError) as error:
        given = " ".join(f"{k}={format_values(v)}" for k, v in values.items())
        raise UsageError(f"--param {given}: {first_line(error)}") from None


def _shape_words(shape: tuple[int, ...]) -> str:
    if shape == ():
        return "one number"
    count = int(np.prod(shape))
    return f"{count} comma-separated numbers"


def run_options(scene, args) -> tuple[float, float | None, Any]:
    t1 = scene.default_t1 if args.t1 is None else args.t1
    dt = scene.default_dt if args.dt is None else args.dt
    for flag, value in (("--t1", t1), ("--dt", dt)):
        if value is not None and not math.isfinite(value):
            raise UsageError(f"{flag} must be a finite number, got {value}")
    if dt is not None and dt <= 0:
        raise UsageError(
            f"--dt must be positive, got {dt} (use --backward to run back)"
        )
    if t1 == 0:
        raise UsageError("--t1 must be non-zero: the run goes from t = 0 to t1")
    if t1 < 0 and not args.backward:
        raise UsageError(
            f"--t1 {t1} is before t0 = 0; pass --backward to run backwards"
        )
    if dt is not None and dt > abs(t1):
        step = f"--dt {dt:g}" if args.dt is not None else f"the scene's step {dt:g}"
        raise UsageError(
            f"{step} is longer than the run (--t1 {t1:g}): the run would be one "
            f"step of {abs(t1):g}, not of dt; pass --dt at most {abs(t1):g} (a "
            "scene's own step is a small fraction of its period)"
        )
    if args.backward:
        t1, dt = -abs(t1), None if dt is None else -abs(dt)
    try:
        check_times(0.0, t1, dt)
    except ValueError as error:
        message = str(error).replace("dt = ", "--dt ", 1)
        raise UsageError(
            message.replace(", or dt=None for adaptive stepping", "")
        ) from None
    if args.solver is not None and args.solver not in SOLVERS:
        raise UsageError(
            f"unknown solver {args.solver!r}; choose from {', '.join(SOLVERS)}"
        )
    solver = None if args.solver is None else SOLVERS[args.solver]()
    if args.batch is not None and args.batch < 1:
        raise UsageError(f"--batch must be at least 1, got {args.batch}")
    return t1, dt, solver


def check_output(path: str | None, flag: str) -> None:
    """Refuse, before the run, an output path that cannot be written."""
    if path is None:
        return
    target = Path(path)
    if path == "" or target.is_dir():
        raise UsageError(f"{flag} {path!r} is a directory; give a file name")
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"{flag} {path}: the folder {parent} does not exist")
    if not os.access(parent, os.W_OK) or (
        target.exists() and not os.access(target, os.W_OK)
    ):
        raise UsageError(f"{flag} {path}: not writable")
    if flag == "--plot":
        _check_plotformat_values(target, flag)


def check_distinct_outputs(save: str | None, plot: str | None) -> None:
    """`--save` and `--plot` naming one file would write the picture over the data
    (and report both written)."""
    if save is None or plot is None:
        return
    same = Path(save).resolve() == Path(plot).resolve()
    if not same and Path(save).exists() and Path(plot).exists():
        same = os.path.samefile(save, plot)
    if same:
        raise UsageError(
            f"--save {save} and --plot {plot} name the same file: the figure would "
            "overwrite the data; give them different names (e.g. run.npz and "
            "run.png)"
        )


def _check_plotformat_values(target: Path, flag: str) -> None:
    try:
        import matplotlib
    except ImportError:
        raise UsageError(
            f"{flag} needs matplotlib: pip install matplotlib (or lagjax[plot])"
        ) from None
    matplotlib.use("Agg")
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    suffix = target.suffix.lstrip(".").lower()
    if suffix not in formats:
        raise UsageError(
            f"{flag} {target}: unknown image format {suffix!r}; use one of "
            f"{', '.join(sorted(formats))} (e.g. run.png)"
        )


def format_values(values: Any) -> str:
    """Numbers as the command prints them: one, or a parenthesised list."""
    flat = [f"{float(x):.10g}" for x in np.ravel(values)]
    return flat[0] if len(flat) == 1 else "(" + ", ".join(flat) + ")"
