"""A sweep over several processes on JAX's own distributed runtime.

After `jax.distributed.initialize()` (multi-controller: one Python process per host
or per accelerator, every process running the same program), process `k` of `P`
runs the chunks `k, k + P, k + 2P, …` of the sweep on its own local devices. No
collective runs while integrating: the processes meet only to gather the results
(in memory) or at a final barrier (on disk). Chunks are dealt round-robin rather than
in contiguous blocks so that a resumed sweep, whose finished chunks may sit anywhere,
is still shared evenly.

Chunk boundaries do not depend on the process count (`lagjax.sweep.ChunkedRun`), so
every member runs through the same compiled program at the same position as in the
one-process sweep, and the results are bit-identical to it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import multihost_utils


def chunks_of_this_process(count: int, todo: Sequence[int] | None = None) -> list[int]:
    """The chunk indices (of `todo`, default all `count`) this process runs."""
    todo = range(count) if todo is None else sorted(todo)
    return list(todo)[jax.process_index() :: jax.process_count()]


def check_a_chunk_for_every_process(count: int) -> None:
    """Refuse, in every process alike, a gathered sweep that leaves a process
    without a chunk (it would have nothing whose shape it could contribute)."""
    if count < jax.process_count():
        raise ValueError(
            f"the sweep has {count} chunk(s) for {jax.process_count()} processes: "
            "give it a smaller chunk_size so that every process has a chunk"
        )


def _pad_members(tree: Any, step: int) -> Any:
    """Zero-pad the leading (member) axis of every leaf to `step`; the padding is
    dropped again after the gather."""

    def pad(leaf):
        leaf = np.asarray(leaf)
        missing = step - leaf.shape[0]
        return np.pad(leaf, [(0, missing)] + [(0, 0)] * (leaf.ndim - 1))

    return jax.tree_util.tree_map(pad, tree)


def gather_chunks(
    pieces: Sequence[Any], mine: Sequence[int], count: int, step: int, size: int
) -> Any:
    """All chunks of the sweep in every process, in member order.

    `pieces[j]` is the result of chunk `mine[j]`, the round-robin share of this
    process. Each process contributes an array of equal shape
    `(ceil(count / P), step, …)` (a process_allgather needs equal shapes), so chunk
    `i` lands at `[i % P, i // P]` of the gathered array.
    """
    processes = jax.process_count()
    per_process = -(-count // processes)
    padded = [_pad_members(piece, step) for piece in pieces]
    filler = jax.tree_util.tree_map(np.zeros_like, padded[0])
    padded += [filler] * (per_process - len(padded))
    local = jax.tree_util.tree_map(lambda *leaves: np.stack(leaves), *padded)
    gathered = multihost_utils.process_allgather(local, tiled=False)

    def reorder(leaf):
        leaf = np.asarray(leaf)
        ordered = [leaf[i % processes, i // processes] for i in range(count)]
        return jnp.asarray(np.concatenate(ordered, axis=0)[:size])

    return jax.tree_util.tree_map(reorder, gathered)


def wait_for_all_processes(name: str) -> None:
    """A barrier across the processes (no-op in one process)."""
    if jax.process_count() > 1:
        multihost_utils.sync_global_devices(name)
