"""`sweep`: one `simulate` call over a batch of initial states and parameters, sharded.

The batch (leading axis of `y0s` and of `args_batch`) is split over all devices with
`jax.sharding` — a one-axis `Mesh` and a `NamedSharding` over it — so the same call
runs on one CPU, on several GPUs, or across hosts after
`jax.distributed.initialize()`. A batch whose size does not divide the device count
is padded (with copies of its last member) and the padding dropped from the result.
Large batches are processed in chunks of `chunk_size`, so memory stays bounded by
one chunk.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from lagjax._integrate.simulate import System, simulate
from lagjax.trajectory import Trajectory

_AXIS = "batch"


def _batch_size(tree: Any) -> int:
    sizes = {int(np.shape(leaf)[0]) for leaf in jax.tree_util.tree_leaves(tree)}
    if len(sizes) != 1:
        raise ValueError(
            f"every batched input needs the same leading size, got {sizes}"
        )
    return sizes.pop()


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


@eqx.filter_jit
def _simulate_members(system, shared_args, simulate_kwargs, members):
    """vmap of `simulate` over (y0, args) members; compiled once per configuration
    (the system, solver and options are hashable Modules and numbers)."""

    def one(member):
        y0, args = member
        return simulate(
            system, y0, args=shared_args if args is None else args, **simulate_kwargs
        )

    return jax.vmap(one)(members)


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
    - `devices`: default `jax.devices()` (all devices of all processes).
    - `simulate_kwargs`: passed to `simulate` (t1, dt, solver, ts, …).

    **Returns:** one `Trajectory` whose arrays have a leading batch axis. Results
    equal `jax.vmap` of `simulate` over the batch up to rounding (XLA compiles the
    per-device batch separately and may vectorize it differently: ≤ 2 ulp measured).
    """
    devices = list(jax.devices() if devices is None else devices)
    shared_args = simulate_kwargs.pop("args", None)
    batched = (y0s, args_batch)
    size = _batch_size(batched)
    step = len(devices) * math.ceil((chunk_size or size) / len(devices))
    mesh = Mesh(np.array(devices), (_AXIS,))
    sharding = NamedSharding(mesh, PartitionSpec(_AXIS))

    run = functools.partial(_simulate_members, system, shared_args, simulate_kwargs)
    pieces = []
    for start in range(0, size, step):
        chunk = _take(batched, start, min(start + step, size))
        padded = _pad(chunk, step)
        # The computation follows its input's sharding: one chunk per device.
        result = run(jax.device_put(padded, sharding))
        pieces.append(_take(result, 0, min(step, size - start)))
    if len(pieces) == 1:
        return pieces[0]
    return jax.tree_util.tree_map(
        lambda *leaves: jnp.concatenate(leaves, axis=0), *pieces
    )
