"""A branch predicate that stays one boolean under `vmap`.

`jax.lax.cond` on a batched predicate becomes a `select`: both branches run for
every member. For a branch that is rare and costly — a pivoted LU when a Cholesky
factor is unsound, a second careful pass over a block of steps that failed — that
turns "rarely" into "always". `any_in_batch(flag)` is `flag` for one member and, under
`vmap`, whether any member's flag is set: one unbatched boolean, so the `cond` stays
a branch (taken for the whole batch when any member needs it; each member then
selects its own answer).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


@jax.custom_batching.custom_vmap
def any_in_batch(flag: jax.Array) -> jax.Array:
    """`flag` itself; under `vmap`, whether it is true for any batch member (one
    unbatched boolean), so that a `lax.cond` on it stays a branch, not a select."""
    return flag


@any_in_batch.def_vmap
def _any_in_batch_rule(axis_size, in_batched, flag):
    del axis_size
    return (jnp.any(flag) if in_batched[0] else flag), False
