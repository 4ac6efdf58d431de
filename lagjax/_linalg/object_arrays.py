"""Arrays held as NumPy object arrays of JAX scalars, the representation in
which `scalarize` evaluates a jaxpr element by element."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np


def to_objects(value: Any) -> np.ndarray:
    """An array (concrete or traced) as an object array of its scalar elements."""
    shape = np.shape(value)
    out = np.empty(shape, dtype=object)
    for index in np.ndindex(*shape):
        out[index] = value[index] if shape else value
    return out


def objects_from_scalars(scalars: Sequence[Any]) -> np.ndarray:
    """A 1-D object array holding the given JAX scalars (no conversion to NumPy)."""
    out = np.empty(len(scalars), dtype=object)
    for i, scalar in enumerate(scalars):
        out[i] = scalar
    return out
