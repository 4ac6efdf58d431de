"""A sweep's parameters as text, and a fingerprint of its inputs.

A directory is resumed only by the same sweep: the fingerprint is a SHA-256 over
the batch (every leaf's shape, dtype and bytes), the shared `args`, the system
(its structure as equinox prints it, and its array parameters' bytes) and the
`simulate` options (as text, arrays by their bytes), and the measure run per member
when it is not `simulate` (its module and qualified name; a `functools.partial`'s
bound arguments as text). It does not see inside Python functions — those a system
wraps (L, H, T, V) or a measure: two that differ only in a function's body, with
the same name, have the same fingerprint.

The chunk size is kept apart from the fingerprint so that a mismatch can be named
as such; versions are recorded but left out, so that upgrading JAX does not orphan
a half-finished sweep.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import json
import re
from typing import Any

import equinox as eqx
import jax
import numpy as np


def _digest(leaf: Any) -> str:
    array = np.ascontiguousarray(np.asarray(leaf))
    hasher = hashlib.sha256(f"{array.dtype.str}{array.shape}".encode())
    hasher.update(array.tobytes())
    return hasher.hexdigest()


def _array_text(leaf: Any) -> str:
    shape = "×".join(map(str, np.shape(leaf))) or "scalar"
    return f"array {shape} {np.asarray(leaf).dtype} sha256:{_digest(leaf)[:16]}"


def _tree_text(tree: Any) -> dict[str, Any]:
    """A pytree's structure (equinox's printout, arrays abbreviated) and the digests
    of its array leaves."""
    arrays = [
        _digest(leaf)
        for leaf in jax.tree_util.tree_leaves(tree)
        if eqx.is_array_like(leaf) and not isinstance(leaf, (bool, int, float))
    ]
    # Memory addresses in a repr change from run to run and from process to process.
    structure = re.sub(
        r" at 0x[0-9a-fA-F]+", "", eqx.tree_pformat(tree, short_arrays=True)
    )
    return {"structure": structure, "arrays": arrays}


def _shapes(tree: Any) -> dict[str, Any] | None:
    if tree is None:
        return None
    return {
        jax.tree_util.keystr(path) or "(array)": {
            "shape": list(np.shape(leaf)),
            "dtype": str(np.asarray(leaf).dtype),
        }
        for path, leaf in jax.tree_util.tree_leaves_with_path(tree)
    }


def _option_text(value: Any) -> Any:
    if eqx.is_array(value) or isinstance(value, np.ndarray):
        return _array_text(value)
    if isinstance(value, (bool, int, float, str, type(None))):
        return value
    return _tree_text(value)


@functools.cache  # reading package metadata takes ~0.1 s; it does not change
def _installed_versions() -> tuple[tuple[str, str], ...]:
    found = {}
    for package in ("lagjax", "jax", "jaxlib", "diffrax", "equinox", "numpy"):
        try:
            found[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            found[package] = "not installed"
    return tuple(found.items())


def versions() -> dict[str, str]:
    """The versions of lagjax and of the packages its results depend on."""
    return dict(_installed_versions())


def measure_text(measure: Any) -> str:
    """A measure function by its module and qualified name (a partial's bound
    arguments added), without the memory addresses that change between runs."""
    if isinstance(measure, functools.partial):
        bound = [_option_text(a) for a in measure.args]
        bound += [f"{k}={_option_text(v)}" for k, v in sorted(measure.keywords.items())]
        return f"partial({measure_text(measure.func)}, {bound})"
    name = getattr(measure, "__qualname__", None) or type(measure).__qualname__
    return f"{getattr(measure, '__module__', None) or '?'}.{name}"


def describe_sweep(
    system: Any,
    y0s: Any,
    args_batch: Any,
    simulate_kwargs: dict[str, Any],
    measure: str | None = None,
) -> tuple[dict[str, Any], str]:
    """The sweep's parameters (JSON-ready) and the fingerprint of its inputs;
    `measure` is `measure_text` of a measure other than `simulate` (None keeps a
    simulate sweep's fingerprint as it was before measures existed)."""
    parameters = {
        "system": type(system).__name__,
        "y0s": _shapes(y0s),
        "args_batch": _shapes(args_batch),
        "simulate_kwargs": {
            name: _option_text(value) for name, value in sorted(simulate_kwargs.items())
        },
    }
    if measure is not None:
        parameters["measure"] = measure
    identity = {
        "parameters": parameters,
        "system": _tree_text(system),
        "y0s": [_digest(leaf) for leaf in jax.tree_util.tree_leaves(y0s)],
        "args_batch": [_digest(leaf) for leaf in jax.tree_util.tree_leaves(args_batch)],
    }
    text = json.dumps(identity, sort_keys=True, default=str)
    return parameters, hashlib.sha256(text.encode()).hexdigest()
