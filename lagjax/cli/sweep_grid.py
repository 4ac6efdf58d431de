"""The members of `lagjax sweep`: a grid (or a list) over scene parameters and
initial conditions, written on the command line.

Each setting names a target and its values:

    --param NAME=VALUES       a scene parameter (NAME[i]=VALUES: entry i of a vector)
    --q0 [COORD=]VALUES       a starting coordinate (COORD: its name or index)
    --qdot0 / --p0 [COORD=]VALUES   a starting velocity or momentum

    VALUES:  1.5              one value, the same for every member
             0.5,1,2          these values
             0.5:2:64         64 values evenly spaced from 0.5 to 2, both included
             1e-3:1:50:log    50 values evenly spaced in log from 1e-3 to 1

A target given more than one value is an *axis*. The members are every combination
of the axes' values (a grid of shape (n₁, n₂, …), the last axis varying fastest:
member k is at `numpy.unravel_index(k, shape)`), or with `--zip` the axes taken
side by side (all of one length n: n members). A vector parameter given as
`NAME=V1,V2,V3` is one value, not an axis.

For every member the scene is built from its parameter values, its start is the
scene's `initial_state()` for those values, and then the `--q0`/`--qdot0`/`--p0`
settings replace entries of that start. All values are checked by the scene's own
rules before anything is compiled.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from lagjax.cli.run import UsageError, first_line

STATE_FLAGS = {"q0": 0, "qdot0": 1, "p0": 1}  # flag -> entry of (q, second)


@dataclasses.dataclass(frozen=True)
class Setting:
    """One `--param`/`--q0`/… setting: its target and its values."""

    flag: str  # "param", "q0", "qdot0" or "p0"
    name: str  # the parameter or coordinate as written (for messages)
    key: str | int  # the parameter's field name, or the state entry's flat index
    entry: int | None  # a vector parameter's flat entry, or None for all of it
    values: np.ndarray  # one row per value: (count,) or, for a whole vector, (1, k)
    text: str  # as given on the command line

    @property
    def is_axis(self) -> bool:
        return self.values.shape[0] > 1


def parse_values(text: str, where: str) -> np.ndarray:
    """`1.5`, `0.5,1,2`, `0.5:2:64` or `1e-3:1:50:log` as an array of floats."""
    parts = text.split(":")
    try:
        if len(parts) == 1:
            values = np.array([float(part) for part in text.split(",")])
        elif len(parts) in (3, 4):
            values = _spaced(parts, where)
        else:
            raise ValueError
    except ValueError:
        raise UsageError(
            f"{where}: {text!r} is not a value list; write one value (1.5), a list "
            "(0.5,1,2), or a range START:STOP:COUNT (0.5:2:64, or 1e-3:1:50:log)"
        ) from None
    if not np.all(np.isfinite(values)):
        raise UsageError(f"{where}: values must be finite numbers, got {text!r}")
    return values


def _spaced(parts: list[str], where: str) -> np.ndarray:
    start, stop = float(parts[0]), float(parts[1])
    count = float(parts[2])
    if count != int(count) or count < 2:
        raise UsageError(
            f"{where}: a range START:STOP:COUNT needs a whole COUNT of at least 2, "
            f"got {parts[2]!r} (for one value, write the value alone)"
        )
    if len(parts) == 4:
        if parts[3] != "log":
            raise ValueError
        if start <= 0 or stop <= 0:
            raise UsageError(
                f"{where}: a log range needs START and STOP above 0, got "
                f"{parts[0]}:{parts[1]}"
            )
        return np.geomspace(start, stop, int(count))
    return np.linspace(start, stop, int(count))


def parameter_setting(text: str, scene_name: str, default: Any) -> Setting:
    """`NAME=VALUES` or `NAME[i]=VALUES` against the scene's fields."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise UsageError(f"--param expects NAME=VALUES, got {text!r}")
    field, entry = _split_entry(name, "--param")
    known = [f.name for f in dataclasses.fields(default)]
    if field not in known:
        raise UsageError(
            f"scene {scene_name} has no parameter {field!r}; its parameters: "
            + (", ".join(known) or "none")
        )
    current = getattr(default, field)
    if not isinstance(current, jax.Array):
        raise UsageError(
            f"--param {field}: a whole number that fixes the scene's array shapes "
            f"(now {current}); it cannot vary across a sweep: run one sweep per value"
        )
    values = parse_values(value, f"--param {name}")
    shape = np.shape(current)
    size = math.prod(shape)
    if entry is not None:
        if not shape or entry >= size:
            raise UsageError(
                f"--param {name}: {field} has {size} entr{'y' if size == 1 else 'ies'}"
                + (
                    "; write it without [i]"
                    if not shape
                    else f"; i from 0 to {size - 1}"
                )
            )
        return Setting("param", name, field, entry, values, text)
    if not shape:
        return Setting("param", name, field, None, values, text)
    if values.size != size:
        raise UsageError(
            f"--param {name}: {field} is a vector of {size} numbers; give all of them "
            f"({name}={','.join(['1'] * size)}) or sweep one entry ({name}[0]={value})"
        )
    return Setting("param", name, field, None, values.reshape(1, size), text)


def _split_entry(name: str, flag: str) -> tuple[str, int | None]:
    """`omega` -> ("omega", None); `omega[2]` -> ("omega", 2)."""
    if not name.endswith("]") or "[" not in name:
        return name, None
    field, _, index = name[:-1].partition("[")
    if not index.isdigit():
        raise UsageError(f"{flag} {name}: the entry in [ ] must be a whole number ≥ 0")
    return field, int(index)


def state_setting(flag: str, text: str, scene_name: str, scene: Any) -> Setting:
    """`[COORD=]VALUES` for --q0, --qdot0 or --p0 against the scene's start."""
    second = "p0" if scene.state_kind == "momentum" else "qdot0"
    if flag != "q0" and flag != second:
        raise UsageError(
            f"--{flag}: scene {scene_name} starts from (q, "
            f"{'p' if second == 'p0' else 'q̇'}); set its start with --q0 and --{second}"
        )
    flat = ravel_pytree(scene.initial_state()[STATE_FLAGS[flag]])[0]
    names = _coordinate_names(scene, flat.size)
    target, sep, value = text.rpartition("=")
    if not sep:
        if flat.size != 1:
            raise UsageError(
                f"--{flag} {text}: scene {scene_name} has {flat.size} coordinates "
                f"({', '.join(names)}); name one: --{flag} {names[0]}={text}"
            )
        target, value = names[0], text
    index = _coordinate_index(target, names, flag)
    values = parse_values(value, f"--{flag} {names[index]}")
    return Setting(flag, names[index], index, None, values, text)


def _coordinate_names(scene: Any, size: int) -> list[str]:
    try:
        names = list(scene.coordinates()[0])
    except ValueError:  # a state whose entries are not the scene's coordinates
        names = []
    return names if len(names) == size else [f"q[{i}]" for i in range(size)]


def _coordinate_index(target: str, names: list[str], flag: str) -> int:
    if target in names:
        return names.index(target)
    if target.isdigit() and int(target) < len(names):
        return int(target)
    raise UsageError(
        f"--{flag} {target}=…: no such coordinate; name one of "
        f"{', '.join(names)} or give its index 0…{len(names) - 1}"
    )


def member_values(settings: list[Setting], zipped: bool) -> tuple[list, tuple]:
    """Per setting, its value for every member (leading axis: members); and the
    grid's shape (one entry per axis; (n,) when zipped)."""
    axes = [s for s in settings if s.is_axis]
    lengths = [s.values.shape[0] for s in axes]
    if zipped:
        if len(set(lengths)) > 1:
            raise UsageError(
                "--zip takes the axes side by side and needs them of one length, got "
                + ", ".join(f"{s.name}: {n}" for s, n in zip(axes, lengths))
                + ": give every range the same COUNT, or leave out --zip for a grid"
            )
        shape = tuple(lengths[:1]) or (1,)
        columns = [s.values for s in axes]
    else:
        shape = tuple(lengths) or (1,)
        grids = np.meshgrid(*[s.values for s in axes], indexing="ij")
        columns = [grid.ravel() for grid in grids]
    members = math.prod(shape)
    per_member, column = [], iter(columns)
    for setting in settings:
        values = next(column) if setting.is_axis else setting.values
        if not setting.is_axis:
            values = np.broadcast_to(values, (members, *values.shape[1:]))
        per_member.append(values)
    return per_member, shape


def _replaced(base: np.ndarray, entries: list[tuple[int, Any]]) -> np.ndarray:
    """A copy of `base` whose flat entries (along its last axes) are replaced."""
    shape = np.shape(base)
    flat = np.array(base, dtype=float).reshape((*shape[:-1], -1) if shape else (1,))
    for index, value in entries:
        flat[..., index] = value
    return flat.reshape(shape)


def split_parameters(
    settings: list[Setting], values: list[np.ndarray], default: Any, members: int
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(fixed, batched): the parameters set to one value for all members, and
    {field: its value for every member} for those with an axis."""
    params = [(s, v) for s, v in zip(settings, values) if s.flag == "param"]
    fixed: dict[str, np.ndarray] = {}
    for setting, _ in params:
        if not setting.is_axis:
            field = str(setting.key)
            if setting.entry is None:
                fixed[field] = setting.values[0]
            else:
                base = fixed.get(field, np.asarray(getattr(default, field)))
                fixed[field] = _replaced(base, [(setting.entry, setting.values[0])])
    batched: dict[str, np.ndarray] = {}
    for setting, column in params:
        if setting.is_axis:
            field = str(setting.key)
            base = fixed.pop(field, None)
            if base is None:
                base = np.asarray(getattr(default, field))
            base = batched.get(field, np.broadcast_to(base, (members, *base.shape)))
            if setting.entry is None:
                batched[field] = np.asarray(column, dtype=float)
            else:
                batched[field] = _replaced(base, [(setting.entry, column)])
    return fixed, batched


def check_parameters(scene_class, fixed: dict, batched: dict) -> None:
    """The scene's own checks on every member's parameters, before any compilation;
    a refused value is named alone, not as one array of all members."""
    for field, column in batched.items():
        try:
            scene_class(**{**fixed, field: column})
        except ValueError:
            for value in np.unique(column, axis=0):
                try:
                    scene_class(**{**fixed, field: value})
                except ValueError as error:
                    raise UsageError(
                        f"--param {field}={_text(value)}: {first_line(error)}"
                    ) from None
    try:
        scene_class(**{**fixed, **batched})
    except ValueError as error:
        raise UsageError(f"--param: {first_line(error)}") from None


def _text(value: Any) -> str:
    return ",".join(f"{x:.10g}" for x in np.ravel(value))


def member_scenes_and_starts(
    scene_class, fixed: dict, batched: dict, settings, values, members: int
) -> tuple[Any, Any]:
    """(args_batch, y0s): one scene per member (None when no parameter varies) and
    one start per member, with the --q0/--qdot0/--p0 entries put in."""
    scenes = None
    if batched:
        scenes = jax.vmap(lambda kw: scene_class(**fixed, **kw))(
            {k: jnp.asarray(v) for k, v in batched.items()}
        )
        starts = jax.vmap(lambda scene: scene.initial_state())(scenes)
    else:
        one = scene_class(**fixed).initial_state()
        starts = jax.tree_util.tree_map(
            lambda x: jnp.broadcast_to(x, (members, *jnp.shape(x))), one
        )
    starts = list(starts)
    for part in (0, 1):
        chosen = [
            (int(s.key), jnp.asarray(v))
            for s, v in zip(settings, values)
            if s.flag != "param" and STATE_FLAGS[s.flag] == part
        ]
        if chosen:
            starts[part] = _replace_entries(starts[part], chosen)
    return scenes, tuple(starts)


def _replace_entries(batch: Any, chosen: list[tuple[int, jax.Array]]) -> Any:
    def one(member, values):
        flat, unravel = ravel_pytree(member)
        for (index, _), value in zip(chosen, values):
            flat = flat.at[index].set(value)
        return unravel(flat)

    return jax.vmap(one)(batch, [v for _, v in chosen])
