"""Concrete values as static parts of a compiled call.

`simulate` runs as one `equinox.filter_jit` call, which traces array leaves and
hashes everything else as the call's static configuration. Some concrete arrays
must reach the trace as values, not tracers: the fixed-step path lays out its
nested scans in Python from the save times (`lagjax._integrate.plan.RunPlan.saving`). A NumPy
array passed in would be traced, and one closed over would not survive either:
inside a trace every `jnp` operation on it — a `diffrax.SubSaveAt` conversion
too — returns a tracer. A concrete `jax.Array` passes through `jnp.asarray` as it
is. `Constant` carries such a pytree as a static argument, hashed by its values,
so equal save times reuse the compilation and others compile anew.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import numpy as np


class Constant:
    """A pytree of concrete values, hashed and compared by structure and values."""

    def __init__(self, value: Any):
        self.value = value
        leaves, treedef = jax.tree_util.tree_flatten(value)
        self._key = treedef, tuple(map(_leaf_key, leaves))

    def __hash__(self) -> int:
        return hash(self._key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Constant) and self._key == other._key


def _leaf_key(leaf: Any) -> Any:
    if not eqx.is_array(leaf):
        return leaf
    array = np.asarray(leaf)
    return array.shape, array.dtype.str, array.tobytes()
