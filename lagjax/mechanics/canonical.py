"""Canonical (symplectic) maps of phase space.

A map (q, p) ↦ (Q, P) is canonical when its Jacobian M satisfies Mᵀ J M = J with
J = [[0, I], [−I, 0]] (Goldstein, *Classical Mechanics*, §9.4). The same test decides
whether one step of a numerical integrator is symplectic.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree


def symplectic_form(n: int, dtype: Any = float) -> jax.Array:
    """The 2n × 2n matrix J = [[0, I], [−I, 0]] in (q, p) ordering."""
    eye = jnp.eye(n, dtype=dtype)
    zero = jnp.zeros((n, n), dtype=dtype)
    return jnp.block([[zero, eye], [-eye, zero]])


def symplectic_defect(
    phase_map: Callable[[Any, Any], tuple[Any, Any]], q: Any, p: Any
) -> jax.Array:
    """max |Mᵀ J M − J| for the Jacobian M of `phase_map(q, p) -> (Q, P)` at (q, p).

    `q` and `p` may be any matching pytrees; the Jacobian is taken in their raveled
    (flat) coordinates with forward-mode autodiff. Zero (to round-off) for a
    canonical map.
    """
    z, unravel = ravel_pytree((q, p))
    n = z.shape[0] // 2

    def flat_map(z_flat):
        return ravel_pytree(phase_map(*unravel(z_flat)))[0]

    jacobian = jax.jacfwd(flat_map)(z)
    form = symplectic_form(n, jacobian.dtype)
    return jnp.max(jnp.abs(jacobian.T @ form @ jacobian - form))
