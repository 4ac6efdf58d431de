"""`sweep`: one `simulate` call — or any per-member measure, such as `lj.megno` — over
a batch of initial states and parameters, sharded.

The batch (leading axis of `y0s` and of `args_batch`) is split over all devices with
`jax.sharding` — a one-axis `Mesh` and a `NamedSharding` over it — so the same call
runs on one CPU or on several GPUs; across processes or hosts, after
`jax.distributed.initialize()`, each process runs its share of the chunks on its own
devices (`lagjax._sweep.processes`). A chunk whose size does not divide the device
count is padded (with copies of its last member) and the padding dropped from the
result. Large batches are processed in chunks of `chunk_size`, so memory stays
bounded by one chunk; `lj.sweep_to_disk` streams the chunks to a directory.

What runs per member is `measure(system, y0, args=…, **kwargs)`: `simulate` by
default, or a function with the same calling convention that returns a pytree of
arrays (`lj.megno`, `lj.chaos_indicators`, or the caller's own). Everything else —
chunks, devices, processes, the disk store, resume, progress — is the same for
both.

Refused by name before anything is compiled: a batch of 0 members, a leaf without
a batch axis, batch inputs of different leading sizes, a chunk size that is not a
positive integer, an empty, foreign or repeated device list, a measure that is
not a function, and inputs whose shapes do not fit the system (one member's
`simulate` or measure is traced, not run, first).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterator, Sequence
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from lagjax._integrate.simulate import System, simulate
from lagjax._integrate.taylor_members import runs_on_taylor_batch, taylor_members
from lagjax._sweep.processes import (
    check_a_chunk_for_every_process,
    chunks_of_this_process,
    gather_chunks,
)

_AXIS = "batch"


def batch_size(y0s: Any, args_batch: Any) -> int:
    """The common leading size of every leaf of `y0s` and `args_batch`, or a
    refusal that names the inputs whose sizes differ (or that have none)."""
    sizes = {}
    for name, tree in (("y0s", y0s), ("args_batch", args_batch)):
        for path, leaf in jax.tree_util.tree_leaves_with_path(tree):
            if not np.shape(leaf):
                raise ValueError(
                    f"{name}{jax.tree_util.keystr(path)} has no batch axis (it is a "
                    "scalar): every leaf of y0s and args_batch needs a leading axis "
                    "over the members — broadcast it (jnp.full(n, value)), or pass a "
                    "parameter shared by all members as args=…"
                )
            sizes[name + jax.tree_util.keystr(path)] = int(np.shape(leaf)[0])
    if not sizes:
        raise ValueError("y0s holds no arrays: nothing to sweep over")
    if len(set(sizes.values())) != 1:
        raise ValueError(
            "every batched input needs the same leading size, got "
            + ", ".join(f"{name}: {size}" for name, size in sizes.items())
            + ": give every leaf one entry per member"
        )
    size = next(iter(sizes.values()))
    if size == 0:
        raise ValueError(
            f"the batch has 0 members ({next(iter(sizes))} has leading size 0): "
            "give at least one member"
        )
    return size


def check_chunk_size(chunk_size: Any) -> None:
    if chunk_size is None:
        return
    remedy = "e.g. chunk_size=4096, or None for the whole batch at once"
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)):
        raise TypeError(
            f"chunk_size must be a positive integer, got {chunk_size!r}: {remedy}"
        )
    if chunk_size < 1:
        raise ValueError(
            f"chunk_size must be a positive integer, got {chunk_size}: {remedy}"
        )


def checked_devices(devices: Sequence[Any] | None) -> list[Any]:
    """`devices` as a list of distinct devices of this process (default: all of
    them), or a refusal naming what is wrong with the list."""
    if devices is None:
        return list(jax.local_devices())
    if isinstance(devices, (str, bytes)) or not isinstance(devices, Sequence):
        raise TypeError(
            f"devices must be a list of JAX devices, got {devices!r}: pass "
            "devices=None for this process's devices, or e.g. jax.local_devices()[:2]"
        )
    devices = list(devices)
    if not devices:
        raise ValueError(
            "devices=[] holds no device to run on: pass devices=None for this "
            "process's devices (jax.local_devices()), or a non-empty list of them"
        )
    local = jax.local_devices()
    for device in devices:
        if device not in local:
            raise ValueError(
                f"devices holds {device!r}, which is not a device of this process: "
                f"choose from jax.local_devices() = {local}"
            )
    if len(set(devices)) != len(devices):
        raise ValueError(
            f"devices lists a device more than once ({devices}): list each once"
        )
    return devices


def _pad(tree: Any, size: int) -> Any:
    """Extend the leading axis to `size` by repeating the last entry."""

    def pad_leaf(leaf):
        leaf = jnp.asarray(leaf)
        missing = size - leaf.shape[0]
        if missing == 0:
            return leaf
        filler = jnp.repeat(leaf[-1:], missing, axis=0)
        return jnp.concatenate([leaf, filler], axis=0)

    return jax.tree_util.tree_map(pad_leaf, tree)


def _take(tree: Any, start: int, stop: int) -> Any:
    return jax.tree_util.tree_map(lambda leaf: leaf[start:stop], tree)


def _first_member(tree: Any) -> Any:
    return jax.tree_util.tree_map(lambda leaf: leaf[0], tree)


def check_measure(measure: Any) -> None:
    if not callable(measure):
        raise TypeError(
            f"measure must be a function called as measure(system, y0, args=…, "
            f"**kwargs), got {measure!r}: e.g. measure=lj.megno with t1=…, dt=…, "
            "or leave it out to run lj.simulate"
        )


@eqx.filter_jit
def _measure_members(system, shared_args, measure, kwargs, members):
    """vmap of `measure` (default `simulate`) over (y0, args) members — or, for
    `simulate` with `lj.Taylor()`, the batch-native Taylor loop
    (`lagjax._integrate.taylor_members`); compiled once per configuration (the
    system, the measure, the solver and options are hashable Modules, functions
    and numbers)."""

    if measure is simulate and runs_on_taylor_batch(kwargs):  # a step per member
        return taylor_members(system, shared_args, kwargs, members)

    def one(member):
        y0, args = member
        return measure(system, y0, args=shared_args if args is None else args, **kwargs)

    return jax.vmap(one)(members)


def _check_a_member_runs(
    system: System, shared_args: Any, measure: Callable, kwargs: dict, member: Any
) -> Any:
    """Trace one member's `measure` (no compilation, no integration), so that
    inputs whose shapes do not fit the system are refused before any chunk runs
    and before a directory is touched. Returns the shapes of its result."""
    y0, args = member
    try:
        return jax.eval_shape(
            lambda y0, args: measure(
                system, y0, args=shared_args if args is None else args, **kwargs
            ),
            y0,
            args,
        )
    except (ValueError, TypeError) as error:
        shapes = jax.tree_util.tree_map(np.shape, member)
        raise type(error)(
            f"the sweep's members cannot run (one member's (y0, args) shapes: "
            f"{shapes}): {error}"
        ) from None


class ChunkedRun(NamedTuple):
    """A sweep cut into chunks of `step` members: chunk `i` holds the members
    `[i * step, min((i + 1) * step, size))`, whichever process runs it, so a member
    meets the same compiled program at the same position in every run."""

    size: int
    step: int
    count: int
    run: Callable[[int], Any]  # chunk index -> its members' results (dispatched)
    member_shapes: Any  # one member's result, as jax.ShapeDtypeStruct leaves


def chunked_run(
    system: System,
    y0s: Any,
    args_batch: Any,
    chunk_size: int | None,
    devices: Sequence[Any] | None,
    kwargs: dict[str, Any],
    measure: Callable[..., Any] = simulate,
) -> ChunkedRun:
    """Check the batch and prepare the chunks of a sweep of `measure` over this
    process's `devices` (default: its local devices)."""
    check_measure(measure)
    check_chunk_size(chunk_size)
    devices = checked_devices(devices)
    kwargs = dict(kwargs)
    shared_args = kwargs.pop("args", None)
    batched = (y0s, args_batch)
    size = batch_size(y0s, args_batch)
    first = _first_member(batched)
    member_shapes = _check_a_member_runs(system, shared_args, measure, kwargs, first)
    step = len(devices) * math.ceil((chunk_size or size) / len(devices))
    mesh = Mesh(np.array(devices), (_AXIS,))
    sharding = NamedSharding(mesh, PartitionSpec(_AXIS))
    measure_members = functools.partial(
        _measure_members, system, shared_args, measure, kwargs
    )

    def run(index: int) -> Any:
        start = index * step
        stop = min(start + step, size)
        # Padded to a full chunk, so every chunk runs the one compiled program;
        # the computation follows its input's sharding: one piece per device.
        padded = _pad(_take(batched, start, stop), step)
        return _take(measure_members(jax.device_put(padded, sharding)), 0, stop - start)

    return ChunkedRun(size, step, math.ceil(size / step), run, member_shapes)


def chunk_results(chunks: ChunkedRun, indices: Sequence[int]) -> Iterator[Any]:
    """The results of the chunks `indices`, in order, each complete, with the next
    chunk already dispatched when one is handed over — so that what the caller does
    with it (copy to the host, write to disk) overlaps the next chunk's integration.

    The next chunk is dispatched only once the current one is done, so one chunk
    runs at a time and memory holds two chunks' results at most (the in-memory
    sweep keeps them all, of course).
    """
    indices = list(indices)
    current = chunks.run(indices[0]) if indices else None
    for position in range(len(indices)):
        jax.block_until_ready(current)
        following = None
        if position + 1 < len(indices):
            following = chunks.run(indices[position + 1])
        yield current
        current = following


def sweep(
    system: System,
    y0s: Any,
    args_batch: Any = None,
    *,
    measure: Callable[..., Any] = simulate,
    chunk_size: int | None = None,
    devices: Sequence[Any] | None = None,
    **kwargs: Any,
) -> Any:
    """`simulate` (or `measure`) for every member of a batch, sharded over `devices`.

    **Arguments:**
    - `y0s`: initial states with a leading batch axis on every leaf.
    - `args_batch`: parameters with the same leading axis, or None to share
      `kwargs["args"]` across the batch.
    - `measure`: what runs per member, called as `measure(system, y0, args=…,
      **kwargs)`; default `lj.simulate`. Any function of one orbit with that calling
      convention that returns a pytree of arrays: `measure=lj.megno, t1=1000.0,
      dt=0.05` maps MEGNO ⟨Y⟩ over the batch. A function defined anew for every
      call (a lambda inside a loop) is compiled anew every call.
    - `chunk_size`: at most this many members at a time (rounded up to a multiple of
      the device count); default: the whole batch at once.
    - `devices`: default `jax.local_devices()` (this process's devices).
    - `kwargs`: passed to `measure` (for `simulate`: t1, dt, solver, ts, …).

    After `jax.distributed.initialize()` (several processes, one program each), every
    process runs every `jax.process_count()`-th chunk on its own devices and the
    chunks are gathered: each process returns the whole sweep, bit-identical to the
    one-process run with the same chunk size and devices per process
    (`lagjax._sweep.processes`). `lj.sweep_to_disk` writes the chunks instead.

    **Returns:** one `Trajectory` whose arrays have a leading batch axis (or the
    measure's pytree, every leaf with a leading batch axis). Results equal
    `jax.vmap` of `simulate` (or of `measure`) over the batch up to rounding (XLA
    compiles the per-device batch separately and may vectorize it differently:
    ≤ 2 ulp measured).
    """
    chunks = chunked_run(system, y0s, args_batch, chunk_size, devices, kwargs, measure)
    if jax.process_count() > 1:
        check_a_chunk_for_every_process(chunks.count)
    mine = chunks_of_this_process(chunks.count)
    pieces = list(chunk_results(chunks, mine))
    if jax.process_count() > 1:
        return gather_chunks(pieces, mine, chunks.count, chunks.step, chunks.size)
    if len(pieces) == 1:
        return pieces[0]
    return jax.tree_util.tree_map(
        lambda *leaves: jnp.concatenate(leaves, axis=0), *pieces
    )
