r"""Cumulative sums as two short windows, for the dense formulation's long chains.

A chain's Lagrangian sums link velocities with `jnp.cumsum` (the n-link pendulum:
$v_k = \sum_{j \le k} \ell_j \dot\theta_j (\cos\theta_j, \sin\theta_j)$). JAX lowers
`cumsum` to an XLA reduce-window spanning the whole axis, and XLA's
`ReduceWindowRewriter` turns every such window longer than its base length (16)
into a two-level tree of pads, reshapes, slices and smaller windows. The derived
equations hold many of them — the cumulative sums of L, of its gradient (their
transposes) and of the n tangents of the mass matrix — and the tree's operations
made the n-link pendulum at n = 24 cost 1.68× its hand-written twin in an RK4 scan
(2.10× for 64 trajectories), where n = 16, below the base, ran at 0.81×.

`with_window_cumsums(fn)` evaluates `fn`'s jaxpr with every `cumsum` along an axis
of `REWRITE_BASE_LENGTH` < n ≤ `MAX_REWRITTEN_LENGTH` entries written as two
windows of about b = ⌈√n⌉ terms, which the rewriter leaves alone (it only matches
a window spanning the axis, undilated): the sums of the b entries ending at each
position, then, by a window dilated by b, the sum of those b apart,

$$ s_i = \sum_{j=i-b+1}^{i} x_j, \qquad
   y_i = \sum_{k=0}^{\lceil n/b \rceil - 1} s_{i-kb} = \sum_{j \le i} x_j $$

(entries before the start are zero). That is 2√n additions per entry, in two
operations, against the tree's dozen; the sums differ from a sequential one by
round-off only. JAX's derivative rules for reduce-window give windows of the same
kinds. Calls (`jit`) are entered; a `cumsum` inside other higher-order primitives
(loops, custom derivatives) is left as written.

Measured (`benchmarks/derivation_overhead.py`, n-link pendulum, RK4 scan, 2-core
CPU): n = 24 1.68 → 1.21× single, 2.10 → 1.22× for 64 trajectories; n = 32 one
trajectory 1.86 → 1.13×.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import jax
import numpy as np
from jax import lax

from lagjax._linalg.jaxpr_interpreter import any_equation, evaluate_jaxpr

# XLA's default `xla_reduce_window_rewrite_base_length`: windows up to this long
# are left as they are, so cumulative sums this short keep JAX's own lowering.
REWRITE_BASE_LENGTH = 16
# Up to here both windows sum at most REWRITE_BASE_LENGTH terms; longer axes keep
# XLA's tree, whose cost per entry does not grow with n.
MAX_REWRITTEN_LENGTH = REWRITE_BASE_LENGTH**2


def _block_length(n: int) -> int:
    """Blocks of about √n: both windows then sum about √n terms per entry."""
    return max(2, math.ceil(math.sqrt(n)))


def dilated_cumsum(x: jax.Array, axis: int, reverse: bool) -> jax.Array:
    """`lax.cumsum(x, axis, reverse)` as two windows of about √n (module docstring)."""
    n = x.shape[axis]
    block = _block_length(n)
    blocks = -(-n // block)
    ones = [1] * x.ndim
    zero = np.zeros((), x.dtype)

    def along_axis(value):
        shape = list(ones)
        shape[axis] = value
        return shape

    def reach(length):
        padding = [(0, 0)] * x.ndim
        padding[axis] = (0, length) if reverse else (length, 0)
        return padding

    # s_i: the sum of the `block` entries ending at i (starting, when reversed).
    window_sums = lax.reduce_window(
        x, zero, lax.add, along_axis(block), ones, reach(block - 1)
    )
    # y_i = s_i + s_{i-b} + s_{i-2b} + …: a window of `blocks` entries b apart.
    return lax.reduce_window(
        window_sums,
        zero,
        lax.add,
        along_axis(blocks),
        ones,
        reach((blocks - 1) * block),
        window_dilation=along_axis(block),
    )


def _window_rule(eqn: Any, operands: list[Any]) -> list[Any]:
    """One equation as written, or as `dilated_cumsum` for a long cumulative sum
    (`evaluate_jaxpr`'s rule)."""
    if _long_cumsum(eqn):
        return [dilated_cumsum(operands[0], **eqn.params)]
    return _bind(eqn, operands)


def _bind(eqn: Any, operands: list[Any]) -> list[Any]:
    """`eqn`'s primitive applied to `operands`, as `jax.core.eval_jaxpr` does."""
    params = eqn.primitive.get_bind_params(eqn.params)
    subfuns: list[Any] = []
    if isinstance(params, tuple):  # JAX before 0.7 also returned sub-functions
        subfuns, params = params
    with eqn.ctx.manager:
        results = eqn.primitive.bind(*subfuns, *operands, **params)
    return results if eqn.primitive.multiple_results else [results]


def _long_cumsum(eqn: Any) -> bool:
    if eqn.primitive.name != "cumsum":
        return False
    n = eqn.invars[0].aval.shape[eqn.params["axis"]]
    return REWRITE_BASE_LENGTH < n <= MAX_REWRITTEN_LENGTH


def with_window_cumsums(fn: Callable[..., jax.Array], *example: Any) -> Callable:
    """`fn` (of arrays, as at `example`, returning one array) with its long
    cumulative sums as two short windows (module docstring); `fn` itself when it
    has none."""
    closed = jax.make_jaxpr(fn)(*example)
    if len(closed.jaxpr.outvars) != 1 or not any_equation(closed.jaxpr, _long_cumsum):
        return fn

    def rewritten(*arrays: Any) -> Any:
        (result,) = evaluate_jaxpr(closed.jaxpr, closed.consts, arrays, _window_rule)
        return result

    return rewritten
