"""The gradient of a scalar function of a few coordinates, for forces ṗ = −∂V/∂q.

Why: a splitting method evaluates the force several times per step, so its compiled
form is most of the step's cost, and on CPU XLA pays per kernel and per recomputed
"expensive" operation (a root, a division). How the gradient is taken decides both.

How: up to `FORWARD_GRADIENT_LIMIT` coordinates, V is re-expressed as arithmetic
on its coordinates' scalars (`scalarize`) and differentiated in forward mode with
the identity basis, one scalar tangent per coordinate. The tangents of the array
formulation — an identity matrix pushed through V's sums and products, which XLA
keeps as a reduction per force — become plain scalar products. When V cannot be
scalarized (an unsupported primitive, a large intermediate) `jax.jacfwd` of V as
written is used; above the limit, reverse mode, whose one pass then beats n
forward ones. The routes agree to round-off.

Measured on Kepler's force, −∂(−1/|q|)/∂q, in lagjax's compensated Störmer–Verlet
loop against the same loop on the hand-written −q/|q|³ (2026-11-26, process CPU
time): one trajectory, 2·10⁵ steps, 1.16× (`jacfwd` of V) → 1.09×; ×64, 4·10⁴
steps, 1.31–1.34× → 1.27–1.33×. (One forward pass per coordinate, stacked, was
1.08× for one trajectory but 1.54–1.57× batched: XLA fuses the stack into one
kernel that recomputes the shared root and divisions for every component.)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._linalg.scalarize import objects_from_scalars, scalarize

# Up to this many coordinates a gradient is taken in forward mode: n tangent passes
# compile to fewer kernels than one reverse pass. Measured on Kepler's force with
# `jacfwd` against `grad`: Störmer-Verlet 65 -> 59 ns/step, Yoshida4 122 -> 112
# (benchmarks/solver_overhead.py --clock cpu).
FORWARD_GRADIENT_LIMIT = 6


def small_gradient(fn: Callable[..., jax.Array]) -> Callable[..., Any]:
    """∂fn/∂x for a scalar `fn(x, *rest)`, x a pytree of floating arrays: forward
    mode on fn's scalar form up to `FORWARD_GRADIENT_LIMIT` coordinates (`jacfwd`
    of fn where it has none), reverse mode above."""

    def gradient(x: Any, *rest: Any) -> Any:
        size = sum(jnp.size(leaf) for leaf in jax.tree_util.tree_leaves(x))
        if size > FORWARD_GRADIENT_LIMIT:
            return jax.grad(fn)(x, *rest)
        x_flat, unravel = ravel_pytree(x)
        floating = jnp.issubdtype(x_flat.dtype, jnp.floating)
        twin = (
            scalarize(lambda xf: fn(unravel(xf), *rest), x_flat) if floating else None
        )
        if twin is None or size == 0:
            return jax.jacfwd(fn)(x, *rest)

        def of_coordinates(xf: jax.Array) -> jax.Array:
            scalars = objects_from_scalars([xf[i] for i in range(size)])
            return jnp.asarray(twin(scalars), x_flat.dtype)

        return unravel(jax.jacfwd(of_coordinates)(x_flat))

    return gradient
