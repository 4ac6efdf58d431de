r"""Poisson brackets of phase-space functions.

For two functions $F(q, p, t)$ and $G(q, p, t)$ of the canonical coordinates,

$$ \{F, G\} = \sum_i \left( \frac{\partial F}{\partial q_i}
   \frac{\partial G}{\partial p_i} - \frac{\partial F}{\partial p_i}
   \frac{\partial G}{\partial q_i} \right) = \nabla F^\top J \, \nabla G,
   \qquad J = \begin{pmatrix} 0 & I \\ -I & 0 \end{pmatrix}. $$

Equivalently, $\{F, G\}$ is the derivative of $F$ along the Hamiltonian vector field
$X_G = J \nabla G = (\partial G/\partial p, -\partial G/\partial q)$ of $G$. That is
how it is computed here: one reverse-mode Jacobian of $G$ gives $X_G$, and one
linearisation of $F$ pushes it forward, so a bracket of two scalars costs one
gradient and one Jacobian-vector product whatever the number of degrees of freedom.

With $G = H$ this is the equation of motion of any observable,
$dF/dt = \{F, H\} + \partial F/\partial t$.

References:
    - The course text, §6.5 (Poisson brackets, eq. 6.48–6.51).
    - Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §9.5.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax.mechanics.signature import (
    call_with_arity,
    check_same_structure,
    positional_arity,
)


def poisson_bracket(
    F: Callable[..., Any], G: Callable[..., Any]
) -> Callable[..., jax.Array]:
    r"""The Poisson bracket $\{F, G\}$ as a function of the phase-space point.

    **Arguments:**

    - `F`, `G`: phase-space functions `f(q, p)`, `f(q, p, t)` or `f(q, p, t, args)`
      returning a real scalar or array.

    **Returns:**

    A function `bracket(q, p, t=0.0, args=None)` returning an array of shape
    `F.shape + G.shape` with

    $$ \{F, G\}_{ab} = \sum_i \left( \frac{\partial F_a}{\partial q_i}
       \frac{\partial G_b}{\partial p_i} - \frac{\partial F_a}{\partial p_i}
       \frac{\partial G_b}{\partial q_i} \right), $$

    the sum running over every entry of the (raveled) pytrees `q` and `p`, which
    must match in structure and shapes. It is jit-, vmap- and grad-able, and is
    itself a valid `F` or `G` for a nested bracket (Jacobi identity).

    References: the course text §6.5; Goldstein, *Classical Mechanics*, §9.5.
    """
    # Count parameters once, here, rather than at every (traced) evaluation.
    f_arity = positional_arity(F, minimum=2, maximum=4, what="F of the bracket {F, G}")
    g_arity = positional_arity(G, minimum=2, maximum=4, what="G of the bracket {F, G}")

    def bracket(q: Any, p: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        check_same_structure(q, p, "q", "p")
        z, unravel = ravel_pytree((q, p))
        n = z.shape[0] // 2

        def f_flat(z_flat: jax.Array) -> jax.Array:
            value = call_with_arity(F, f_arity, *unravel(z_flat), t, args)
            return _real_array(value, "F of the bracket {F, G}")

        def g_flat(z_flat: jax.Array) -> jax.Array:
            value = call_with_arity(G, g_arity, *unravel(z_flat), t, args)
            return _real_array(value, "G of the bracket {F, G}")

        grad_g = jax.jacrev(g_flat)(z)  # G.shape + (2n,)
        # X_G = J ∇G for every component of G, in (q, p) ordering.
        flow_g = jnp.concatenate([grad_g[..., n:], -grad_g[..., :n]], axis=-1)
        f_value, f_linear = jax.linearize(f_flat, z)
        along_flow = jax.vmap(f_linear)(flow_g.reshape(-1, 2 * n))  # (|G|,) + F.shape
        g_shape = grad_g.shape[:-1]
        return jnp.moveaxis(along_flow, 0, -1).reshape(f_value.shape + g_shape)

    return bracket


def _real_array(value: Any, what: str) -> jax.Array:
    """Trace-time check that a phase-space function returned one real array."""
    if isinstance(value, (tuple, list, dict)):
        raise TypeError(
            f"{what} must return a single array, not a {type(value).__name__}"
        )
    value = jnp.asarray(value)
    if not jnp.issubdtype(value.dtype, jnp.floating):
        raise ValueError(f"{what} must return real floats, but returned {value.dtype}")
    return value
