"""`sweep_to_disk`: a sweep whose results survive — streamed to a directory chunk
by chunk, resumed after a crash, shared among JAX's processes.

Every refusal comes before any integration, and all but the directory's own before
the directory is touched: the batch's (`lagjax.sweep.chunked_run`: no members, no
batch axis, sizes or shapes that do not fit, chunk size, devices), a path that is a
file or cannot be written, a directory that holds other files or another sweep's
chunks (fingerprint, `lagjax._sweep.fingerprint`), or the same sweep cut into
other chunks. `simulate` members run with `throw=False`: a failing member is marked
by its `RESULTS` code and the others are kept; a measure's member by a non-finite
value (`lagjax._sweep.store`).

The next chunk is dispatched before the current one is copied to the host and
written, so that writing overlaps integrating (`lagjax.sweep.chunk_results`: two
chunks in memory at most).
"""

from __future__ import annotations

import json
import os
import socket
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import jax

from lagjax._integrate.simulate import System, simulate
from lagjax._sweep.fingerprint import describe_sweep, measure_text, versions
from lagjax._sweep.processes import chunks_of_this_process, wait_for_all_processes
from lagjax._sweep.progress import ProgressMeter, SweepProgress
from lagjax._sweep.reader import SweepStore
from lagjax._sweep.store import (
    FORMAT,
    completed_chunks,
    field_descriptions,
    measure_arrays,
    measure_field_names,
    read_index,
    remove_own_leftovers,
    result_messages,
    trajectory_arrays,
    write_chunk,
    write_index,
)
from lagjax.sweep import ChunkedRun, chunk_results, chunked_run

DEFAULT_CHUNK_SIZE = 4096


def _writable_directory(out_dir: Path, tag: str) -> None:
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(
            f"out_dir {str(out_dir)!r} is a file, not a directory: give the path of "
            "a new or empty directory"
        )
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        probe = out_dir / f".write-probe-{tag}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as error:
        raise ValueError(
            f"out_dir {str(out_dir)!r} is not writable ({error.strerror or error}): "
            "give a directory you can create and write to"
        ) from None


def _new_index(
    fingerprint: str, parameters: dict, chunks: ChunkedRun, attributes: dict
) -> dict:
    return {
        "format": FORMAT,
        "attributes": attributes,
        "fingerprint": fingerprint,
        "members": chunks.size,
        "chunk_size": chunks.step,
        "chunk_count": chunks.count,
        "parameters": parameters,
        "versions": versions(),
        "fields": {},
        "chunks": [],
        "result_messages": {},
        "complete": False,
    }


def _open_directory(
    out_dir: Path,
    fingerprint: str,
    parameters: dict,
    chunks: ChunkedRun,
    attributes: dict,
    tag: str,
) -> dict[str, Any]:
    """The directory's index, after refusing anything but this sweep's own."""
    _writable_directory(out_dir, tag)
    index = read_index(out_dir)
    if index is None:
        others = sorted(p.name for p in out_dir.iterdir() if not p.name.startswith("."))
        if others:
            raise ValueError(
                f"out_dir {str(out_dir)!r} holds files but no sweep index "
                f"({', '.join(others[:5])}): give a new or empty directory"
            )
        index = _new_index(fingerprint, parameters, chunks, attributes)
        write_index(out_dir, index, tag)
        return index
    if index.get("format") != FORMAT or index.get("fingerprint") != fingerprint:
        raise ValueError(
            f"out_dir {str(out_dir)!r} holds another sweep's chunks (fingerprint "
            f"{str(index.get('fingerprint'))[:12]}…, this sweep's {fingerprint[:12]}…):"
            " give a new directory, or remove that one to start over"
        )
    if index["chunk_size"] != chunks.step:
        raise ValueError(
            f"out_dir {str(out_dir)!r} holds this sweep in chunks of "
            f"{index['chunk_size']} members, not {chunks.step}: pass "
            f"chunk_size={index['chunk_size']} to resume it"
        )
    return index


def _json_ready(attributes: Any) -> dict[str, Any]:
    if attributes is None:
        return {}
    if not isinstance(attributes, dict):
        raise TypeError(
            f"attributes must be a dict of JSON values, got {type(attributes).__name__}"
        )
    try:
        json.dumps(attributes)
    except (TypeError, ValueError) as error:
        raise TypeError(
            f"attributes must hold JSON values only ({error}): convert arrays with "
            ".tolist()"
        ) from None
    return attributes


def _record(out_dir: Path, index: dict, done: dict[int, dict], tag: str) -> None:
    index["chunks"] = list(done.values())
    index["complete"] = len(done) == index["chunk_count"]
    for entry in done.values():
        index["result_messages"].update(entry["result_messages"])
    write_index(out_dir, index, tag)


def _member_arrays(output: Any, measure: Callable) -> tuple[dict, dict]:
    """A chunk's results as named host arrays, and the messages of its codes."""
    if measure is simulate:
        return trajectory_arrays(output), result_messages(output)
    return measure_arrays(output), {}


def sweep_to_disk(
    system: System,
    y0s: Any,
    args_batch: Any = None,
    *,
    out_dir: str | os.PathLike,
    measure: Callable[..., Any] = simulate,
    chunk_size: int | None = DEFAULT_CHUNK_SIZE,
    devices: Sequence[Any] | None = None,
    progress: bool | Callable[[SweepProgress], Any] = False,
    attributes: dict[str, Any] | None = None,
    **kwargs: Any,
) -> SweepStore:
    """`lj.sweep`, streamed to `out_dir` in chunks that survive the process.

    **Arguments:** as `lj.sweep`, and
    - `out_dir`: a new or empty directory, or one holding this same sweep (then it is
      resumed after its completed chunks). The format: `lagjax._sweep.store`.
    - `measure`: what runs per member (as `lj.sweep`); default `lj.simulate`. The
      fields of another measure's result are stored by name (`value`, or the
      leaves' paths) with `finite`, the failure mark of a member.
    - `chunk_size`: members per chunk file (rounded up to a multiple of the device
      count); default 4096. A resumed sweep needs the same.
    - `progress`: True prints a line per chunk (members done, rate, time left); a
      callable receives a `SweepProgress` per chunk.
    - `attributes`: the caller's notes on the sweep, JSON-ready (what each member
      is, say: `lagjax sweep` records its grid), kept in `index.json` as written
      by the call that created the directory.
    - `kwargs`: passed to `measure`; `simulate` runs with `throw=False`.

    After `jax.distributed.initialize()` every process writes its share of the chunks
    (`lagjax._sweep.processes`) to the same directory, which must then be on a file
    system all processes see.

    **Returns:** a `SweepStore` of the directory (`store.array("q")`, …).
    """
    if measure is simulate:
        if kwargs.get("throw", False):
            raise ValueError(
                "sweep_to_disk marks a failing member by its RESULTS code instead of "
                "raising: leave out throw=True"
            )
        kwargs["throw"] = False
    attributes = _json_ready(attributes)
    chunks = chunked_run(system, y0s, args_batch, chunk_size, devices, kwargs, measure)
    named = None if measure is simulate else measure_text(measure)
    if named is not None:
        measure_field_names(chunks.member_shapes)  # refuse clashing names now
    parameters, fingerprint = describe_sweep(system, y0s, args_batch, kwargs, named)
    parameters["chunk_size"] = chunk_size
    out_dir = Path(out_dir)
    tag = f"{socket.gethostname()}-p{jax.process_index()}"
    index = _open_directory(out_dir, fingerprint, parameters, chunks, attributes, tag)
    remove_own_leftovers(out_dir, tag)
    done = completed_chunks(out_dir)
    # Every process must deal the same to-do list: none writes a chunk before all
    # have listed the directory (else a late process, seeing an early one's new
    # chunks, deals the rest differently and some chunks are run by no one).
    wait_for_all_processes("lagjax sweep_to_disk: chunks listed")
    mine = chunks_of_this_process(
        chunks.count, [i for i in range(chunks.count) if i not in done]
    )
    meter = ProgressMeter(
        progress,
        chunks.size,
        sum(e["stop"] - e["start"] for e in done.values()),
        sum(min(chunks.step, chunks.size - i * chunks.step) for i in mine),
        sum(e["failed"] for e in done.values()),
        jax.process_index(),
        jax.process_count(),
    )
    for chunk, output in zip(mine, chunk_results(chunks, mine), strict=True):
        arrays, messages = _member_arrays(output, measure)
        entry = write_chunk(out_dir, chunk, chunk * chunks.step, arrays, messages, tag)
        done[chunk] = entry
        index["fields"] = index["fields"] or field_descriptions(arrays)
        _record(out_dir, index, dict(sorted(done.items())), tag)
        meter.chunk_written(chunk, entry["stop"] - entry["start"], entry["failed"])
    if jax.process_count() > 1:
        # The processes wrote their chunks side by side; one lists them all.
        wait_for_all_processes("lagjax sweep_to_disk: chunks written")
        if jax.process_index() == 0:
            everything = read_index(out_dir) or index
            _record(out_dir, everything, completed_chunks(out_dir), tag)
        wait_for_all_processes("lagjax sweep_to_disk: index written")
    return SweepStore(out_dir)
