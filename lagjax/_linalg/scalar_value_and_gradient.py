"""A scalar function's value and gradient at once, as arithmetic on scalars.

Why: a time-transformed kick needs the potential and its gradient together (the
weight $w(-V)$ times the force), a drift the kinetic energy and the velocity, and
the extrapolated leapfrog evaluates them $n_k$ times a step. On CPU XLA pays per
kernel: the array form of a pairwise potential's gradient (an (N, N, d) separation
array, a masked sum, a small dot) compiles to about six kernels and a dot per
evaluation. The same arithmetic on the coordinates' scalars fuses into far fewer
kernels. Measured on the Pythagorean problem (`TimeTransformed(GraggBulirschStoer)`,
3,393 steps, one pinned core, inside `jax.jit`): 6.5 µs a step as written, 3.3 µs on
scalars (`benchmarks/close_encounters.py`).

How: `jax.value_and_grad` of the function on its flattened arguments is traced to
a jaxpr and evaluated on scalars (`lagjax._linalg.scalarize.scalarize_outputs`).
Where that is impossible (an unsupported primitive, an intermediate larger than
`MAX_SCALARIZED_SIZE`) or there are more than `SCALAR_GRADIENT_LIMIT`
coordinates, `jax.value_and_grad` runs as written; the result is the same either
way to round-off, only the speed differs.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._linalg.scalarize import objects_from_scalars, scalarize_outputs

# Above this many coordinates the scalar form's unrolled code (quadratic in the
# number of bodies for a pair potential) stops paying for its compile time.
SCALAR_GRADIENT_LIMIT = 32


def value_and_scalar_gradient(
    fn: Callable[..., jax.Array], *xs: Any
) -> tuple[jax.Array, tuple[Any, ...]]:
    """`(fn(*xs), (∂fn/∂x for x in xs))` for a scalar `fn` of pytrees of floating
    arrays, computed on scalars where it can be (module docstring)."""
    argnums = tuple(range(len(xs)))
    flats, unravels = zip(*(ravel_pytree(x) for x in xs))
    size = sum(flat.size for flat in flats)

    def of_flat(*flat_xs: jax.Array) -> tuple[jax.Array, tuple[Any, ...]]:
        unflat = [unravel(flat) for unravel, flat in zip(unravels, flat_xs)]
        return jax.value_and_grad(lambda *a: fn(*a), argnums=argnums)(*unflat)

    twin = (
        scalarize_outputs(lambda *f: _flat_outputs(of_flat(*f)), *flats)
        if 0 < size <= SCALAR_GRADIENT_LIMIT
        else None
    )
    if twin is None:
        return jax.value_and_grad(fn, argnums=argnums)(*xs)
    value, *gradients = twin(
        *(objects_from_scalars([flat[i] for i in range(flat.size)]) for flat in flats)
    )
    return value[()], tuple(
        unravel(_stacked(gradient, flat.dtype))
        for unravel, flat, gradient in zip(unravels, flats, gradients)
    )


def _stacked(scalars: Any, dtype: Any) -> jax.Array:
    """An object array of JAX scalars as one flat array."""
    if scalars.size == 0:
        return jnp.zeros(0, dtype)
    return jnp.stack(list(scalars.reshape(-1))).astype(dtype)


def _flat_outputs(result: tuple[jax.Array, tuple[Any, ...]]) -> list[jax.Array]:
    """(value, gradients) as [value, flat gradient per argument]."""
    value, gradients = result
    return [value, *(ravel_pytree(gradient)[0] for gradient in gradients)]
