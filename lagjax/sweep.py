"""`sweep`: one `simulate` call over a batch of initial states and parameters, sharded.

The batch (leading axis of `y0s` and of `args_batch`) is split over all devices with
`jax.sharding` — a one-axis `Mesh` and a `NamedSharding` over it — so the same call
runs on one CPU or on several GPUs; across processes or hosts, after
`jax.distributed.initialize()`, each process runs its share of the chunks on its own
devices (`lagjax._sweep.processes`). A chunk whose size does not divide the device
count is padded (with copies of its last member) and the padding dropped from the
result. Large batches are processed in chunks of `chunk_size`, so memory stays
bounded by one chunk; `lj.sweep_to_disk` streams the chunks to a directory.

Refused by name before anything is compiled: a batch of 0 members, a leaf without
a batch axis, batch inputs of different leading sizes, a chunk size that is not a
positive integer, an empty, foreign or repeated device list, and inputs whose
shapes do not fit the system (one member's `simulate` is traced, not run, first).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
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
from lagjax.trajectory import Trajectory

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


@eqx.filter_jit
def _simulate_members(system, shared_args, simulate_kwargs, members):
    """vmap of `simulate` over (y0, args) members — or, for `lj.Taylor()`, the
    batch-native Taylor loop (`lagjax._integrate.taylor_members`); compiled once
    per configuration (the system, solver and options are hashable Modules and
    numbers)."""

    if runs_on_taylor_batch(simulate_kwargs):  # one order, a step per member
        return taylor_members(system, shared_args, simulate_kwargs, members)

    def one(member):
        y0, args = member
        return simulate(
            system, y0, args=shared_args if args is None else args, **simulate_kwargs
        )

    return jax.vmap(one)(members)


def _check_a_member_runs(
    system: System, shared_args: Any, simulate_kwargs: dict[str, Any], member: Any
) -> None:
    """Trace one member's `simulate` (no compilation, no integration), so that
    inputs whose shapes do not fit the system are refused before any chunk runs
    and before a directory is touched."""
    y0, args = member
    try:
        jax.eval_shape(
            lambda y0, args: simulate(
                system,
                y0,
                args=shared_args if args is None else args,
                **simulate_kwargs,
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
    run: Callable[[int], Trajectory]  # chunk index -> its members' trajectories


def chunked_run(
    system: System,
    y0s: Any,
    args_batch: Any,
    chunk_size: int | None,
    devices: Sequence[Any] | None,
    simulate_kwargs: dict[str, Any],
) -> ChunkedRun:
    """Check the batch and prepare the chunks of a sweep over this process's
    `devices` (default: its local devices)."""
    check_chunk_size(chunk_size)
    devices = checked_devices(devices)
    simulate_kwargs = dict(simulate_kwargs)
    shared_args = simulate_kwargs.pop("args", None)
    batched = (y0s, args_batch)
    size = batch_size(y0s, args_batch)
    _check_a_member_runs(system, shared_args, simulate_kwargs, _first_member(batched))
    step = len(devices) * math.ceil((chunk_size or size) / len(devices))
    mesh = Mesh(np.array(devices), (_AXIS,))
    sharding = NamedSharding(mesh, PartitionSpec(_AXIS))
    simulate_members = functools.partial(
        _simulate_members, system, shared_args, simulate_kwargs
    )

    def run(index: int) -> Trajectory:
        start = index * step
        stop = min(start + step, size)
        # Padded to a full chunk, so every chunk runs the one compiled program;
        # the computation follows its input's sharding: one piece per device.
        padded = _pad(_take(batched, start, stop), step)
        return _take(
            simulate_members(jax.device_put(padded, sharding)), 0, stop - start
        )

    return ChunkedRun(size, step, math.ceil(size / step), run)


def sweep(
    system: System,
    y0s: Any,
    args_batch: Any = None,
    *,
    chunk_size: int | None = None,
    devices: Sequence[Any] | None = None,
    **simulate_kwargs: Any,
) -> Trajectory:
    """`simulate` for every member of a batch, sharded over `devices`.

    **Arguments:**
    - `y0s`: initial states with a leading batch axis on every leaf.
    - `args_batch`: parameters with the same leading axis, or None to share
      `simulate_kwargs["args"]` across the batch.
    - `chunk_size`: at most this many members at a time (rounded up to a multiple of
      the device count); default: the whole batch at once.
    - `devices`: default `jax.local_devices()` (this process's devices).
    - `simulate_kwargs`: passed to `simulate` (t1, dt, solver, ts, …).

    After `jax.distributed.initialize()` (several processes, one program each), every
    process runs every `jax.process_count()`-th chunk on its own devices and the
    chunks are gathered: each process returns the whole sweep, bit-identical to the
    one-process run with the same chunk size and devices per process
    (`lagjax._sweep.processes`). `lj.sweep_to_disk` writes the chunks instead.

    **Returns:** one `Trajectory` whose arrays have a leading batch axis. Results
    equal `jax.vmap` of `simulate` over the batch up to rounding (XLA compiles the
    per-device batch separately and may vectorize it differently: ≤ 2 ulp measured).
    """
    chunks = chunked_run(system, y0s, args_batch, chunk_size, devices, simulate_kwargs)
    if jax.process_count() > 1:
        check_a_chunk_for_every_process(chunks.count)
    mine = chunks_of_this_process(chunks.count)
    pieces = [chunks.run(index) for index in mine]
    if jax.process_count() > 1:
        return gather_chunks(pieces, mine, chunks.count, chunks.step, chunks.size)
    if len(pieces) == 1:
        return pieces[0]
    return jax.tree_util.tree_map(
        lambda *leaves: jnp.concatenate(leaves, axis=0), *pieces
    )
