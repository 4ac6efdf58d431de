"""The directory a sweep streams to: `.npy` chunks and a JSON index, readable by
numpy alone.

```
out_dir/
  index.json          the sweep's parameters, fingerprint, versions, fields, chunks
  chunk_000000/       members [0, step): one .npy per field, and chunk.json
    ts.npy  q.npy  p.npy  result.npy  stats.num_steps.npy  …
  chunk_000001/       …
```

Each field holds one array per chunk whose leading axis is the chunk's members:
`ts`, the state (`q` and `p` or `qdot`; a pytree state gives `q.0`, `q.x`, … one file
per leaf), `result` (diffrax's `RESULTS` code: 0 for success; `index.json` maps the
codes that occurred to their messages) and `stats.*` (the run statistics).

A sweep of another measure (`lj.megno`, say) stores the leaves of its result
instead: `value` for a single array, the leaves' paths for a pytree (`megno`,
`fli`, `lyapunov` for `lj.chaos_indicators`), and `finite`: False for a member
with a NaN or inf anywhere in its result, its failure mark. A measure returns no
`RESULTS` code; one that raises on a failing member (as `lj.megno` does on a
non-finite orbit) stops its chunk instead.

A chunk is complete when its directory exists: it is written under a temporary
name and renamed in one step (atomic on a POSIX file system), so a crash leaves
either the whole chunk or none of it. `index.json` is rewritten (also atomically)
after every chunk and lists the completed ones; a resumed sweep rescans the
directories, which stay the truth when several processes write at once.
"""

from __future__ import annotations

import functools
import json
import os
import re
import shutil
from pathlib import Path
from typing import Any

import diffrax
import jax
import numpy as np

FORMAT = "lagjax-sweep/1"
INDEX = "index.json"
_CHUNK = re.compile(r"^chunk_(\d{6})$")


@functools.cache  # asked once per chunk; the codes do not change
def success_codes() -> tuple[int, ...]:
    """Codes of a member that ran as asked: a success, or an event that ended it.

    Read from diffrax when asked, not on import: reading a code is a JAX
    computation, and JAX's backend must not start before
    `jax.distributed.initialize()`.
    """
    items = (diffrax.RESULTS.successful, diffrax.RESULTS.event_occurred)
    # An equinox enumeration item holds its code(s) as its one array leaf.
    return tuple(int(jax.tree_util.tree_leaves(item)[0]) for item in items)


def result_messages(traj: Any) -> dict[str, str]:
    """diffrax's message for every `RESULTS` code in a batched trajectory."""
    (codes,) = jax.tree_util.tree_leaves(traj.result)
    codes = np.asarray(codes)
    messages = {}
    for code in np.unique(codes):
        first = int(np.argmax(codes == code))
        member = jax.tree_util.tree_map(lambda v, i=first: v[i], traj.result)
        messages[str(int(code))] = str(diffrax.RESULTS[member])
    return messages


FAILURE_FIELDS = ("result", "stats.finite", "finite")


def failed_members(arrays: dict[str, np.ndarray]) -> np.ndarray:
    """True for a member whose `RESULTS` code is a failure, or whose state (or
    measured value) stopped being finite: a fixed-step run that saves at `ts` can
    end with NaN states and a successful code (jax 0.10.2, diffrax 0.7.2), so both
    are read."""
    present = [name for name in FAILURE_FIELDS if name in arrays]
    failed = np.zeros(len(arrays[present[0]]), dtype=bool)
    if "result" in arrays:
        failed |= ~np.isin(arrays["result"], success_codes())
    for name in ("stats.finite", "finite"):
        if name in arrays:
            failed |= ~arrays[name].astype(bool)
    return failed


def chunk_name(index: int) -> str:
    return f"chunk_{index:06d}"


def _leaf_name(prefix: str, path: tuple[Any, ...]) -> str:
    """`q` for an array state, `q.0` / `q.x` for the leaves of a pytree state."""
    keys = [
        str(getattr(key, "key", getattr(key, "idx", getattr(key, "name", key))))
        for key in path
    ]
    return ".".join([prefix, *keys])


def trajectory_arrays(traj: Any) -> dict[str, np.ndarray]:
    """A batched `Trajectory`'s results as named host arrays (member axis first)."""
    second = "p" if traj.is_hamiltonian else "qdot"
    arrays = {"ts": np.asarray(traj.ts)}
    for prefix, tree in (("q", traj.ys[0]), (second, traj.ys[1])):
        for path, leaf in jax.tree_util.tree_leaves_with_path(tree):
            arrays[_leaf_name(prefix, path)] = np.asarray(leaf)
    (codes,) = jax.tree_util.tree_leaves(traj.result)
    arrays["result"] = np.asarray(codes)
    for key, value in sorted(traj.run_stats.items()):
        arrays[f"stats.{key}"] = np.asarray(value)
    return arrays


def measure_field_names(member_shapes: Any) -> list[str]:
    """The fields of a measure's result (one member's shapes): `value` for a single
    array, the leaves' paths for a pytree; refuses a pytree that names a leaf like
    the failure mark (`finite`) or twice."""
    leaves = jax.tree_util.tree_leaves_with_path(member_shapes)
    if len(leaves) == 1 and not leaves[0][0]:
        return ["value"]
    names = [_leaf_name("", path).lstrip(".") for path, _ in leaves]
    if not names:
        raise ValueError(
            "the measure returns no arrays: return the value(s) of one member, "
            "e.g. a scalar or a pytree of arrays"
        )
    clashes = sorted({n for n in names if n == "finite" or names.count(n) > 1})
    if clashes:
        raise ValueError(
            f"the measure's result names the field(s) {clashes} twice or like the "
            "store's failure mark 'finite': rename those leaves (a dict key, say)"
        )
    return names


def measure_arrays(values: Any) -> dict[str, np.ndarray]:
    """A batched measure's result as named host arrays, and `finite`: whether every
    entry of a member's result is finite."""
    names = measure_field_names(values)
    arrays = {
        name: np.asarray(leaf)
        for name, leaf in zip(names, jax.tree_util.tree_leaves(values), strict=True)
    }
    finite = np.ones(next(iter(arrays.values())).shape[0], dtype=bool)
    for array in arrays.values():
        if np.issubdtype(array.dtype, np.inexact):
            finite &= np.isfinite(array.reshape(array.shape[0], -1)).all(axis=1)
    arrays["finite"] = finite
    return arrays


def field_descriptions(arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """Per field: its file, and the shape and dtype of one member's entry."""
    return {
        name: {
            "file": f"{name}.npy",
            "member_shape": list(array.shape[1:]),
            "dtype": array.dtype.str,
        }
        for name, array in arrays.items()
    }


def _write_json(path: Path, content: dict[str, Any], tag: str) -> None:
    """Write under a temporary name, then rename: readers never see half a file."""
    temporary = path.with_name(f".{path.name}.tmp-{tag}")
    temporary.write_text(json.dumps(content, indent=1, sort_keys=True) + "\n")
    os.replace(temporary, path)


def read_index(out_dir: Path) -> dict[str, Any] | None:
    path = out_dir / INDEX
    return json.loads(path.read_text()) if path.exists() else None


def write_index(out_dir: Path, index: dict[str, Any], tag: str) -> None:
    _write_json(out_dir / INDEX, index, tag)


def write_chunk(
    out_dir: Path,
    index: int,
    start: int,
    arrays: dict[str, np.ndarray],
    result_messages: dict[str, str],
    tag: str,
) -> dict[str, Any]:
    """Write one chunk atomically; returns its entry for the index."""
    final = out_dir / chunk_name(index)
    temporary = out_dir / f".{chunk_name(index)}.tmp-{tag}"
    shutil.rmtree(temporary, ignore_errors=True)
    temporary.mkdir()
    for name, array in arrays.items():
        np.save(temporary / f"{name}.npy", array, allow_pickle=False)
    members = len(next(iter(arrays.values())))
    entry = {
        "index": index,
        "dir": chunk_name(index),
        "start": start,
        "stop": start + members,
        "failed": int(np.count_nonzero(failed_members(arrays))),
        "result_messages": result_messages,
    }
    _write_json(temporary / "chunk.json", entry, tag)
    try:
        os.rename(temporary, final)
    except OSError:  # another process finished the same chunk first: same content
        if not (final / "chunk.json").exists():
            raise
        shutil.rmtree(temporary)
    return entry


def completed_chunks(out_dir: Path) -> dict[int, dict[str, Any]]:
    """The chunks on disk (each complete by construction), by index."""
    found = {}
    for path in out_dir.iterdir() if out_dir.exists() else ():
        match = _CHUNK.match(path.name)
        if match and (path / "chunk.json").exists():
            found[int(match.group(1))] = json.loads((path / "chunk.json").read_text())
    return dict(sorted(found.items()))


def remove_own_leftovers(out_dir: Path, tag: str) -> None:
    """Temporary files of a run of this process that crashed mid-write."""
    for path in out_dir.glob(f".*.tmp-{tag}"):
        shutil.rmtree(path) if path.is_dir() else path.unlink()
