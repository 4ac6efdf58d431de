r"""The Euler–Lagrange accelerations of a network-sized Lagrangian.

`euler_lagrange_acceleration` is built for closed-form Lagrangians: for up to six
coordinates it re-expresses L as scalar arithmetic and sends every scalar tangent
through L separately, which fuses a whole integration step into one kernel. When L
is a neural network its cost is its matrix products, and each of those passes
repeats them: a 4-128-128-1 MLP's training step runs 0.73× the published Lagrangian
neural network formula and its gradient compiles for a minute. What a network needs
is the fewest passes. The equations

$$ M\ddot q = \frac{\partial L}{\partial q}
   - \frac{\partial^2 L}{\partial\dot q\,\partial q}\dot q
   - \frac{\partial^2 L}{\partial\dot q\,\partial t} + Q,
   \qquad M = \frac{\partial^2 L}{\partial\dot q\,\partial\dot q}, $$

take one gradient of L (its q-part is $\partial L/\partial q$) and n + 1
Hessian–vector products of it: along $(0, e_k, 0)$ for the columns of M and along
$(\dot q, 0, 1)$ in $(q, \dot q, t)$ for the transport term. Here they are one
forward-over-reverse pass, the n + 1 tangents batched by `vmap` around a single
reverse pass. For an MLP with h-wide hidden layers this is about 2(n + 2) products
of an h×h matrix with a vector per state (8 at n = 2). Forward-over-forward
(Taylor-mode) second derivatives need 1 + 2n + n(n+1)/2 + n such products, 10 at
n = 2; nested `jacfwd` measured 0.64× the published formula's speed per training
step, this formulation 1.5× (`benchmarks/lnn_training.py`, which also counts the
products and shows why no exact formulation can reach 5× there).

`Lagrangian` uses this formulation when L is an equinox Module with floating array
leaves — a network — or when asked with `formulation="network"`.

References: M. Cranmer et al., "Lagrangian Neural Networks" (2020),
arXiv:2003.04630, eq. 6; M. Lutter, C. Ritter, J. Peters, "Deep Lagrangian
Networks" (ICLR 2019); B. A. Pearlmutter, "Fast exact multiplication by the
Hessian", Neural Computation 6 (1994).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._linalg.small_solves import solve_dense
from lagjax.mechanics.euler_lagrange import apply_singular_check, flat_lagrangian

FlatLagrangian = Callable[[jax.Array, jax.Array, jax.Array], jax.Array]


def holds_network(function: Any) -> bool:
    """Whether `function` is an equinox Module with floating array leaves (a
    network, or any Module with trainable arrays): the rule by which `Lagrangian`
    picks this formulation."""
    return isinstance(function, eqx.Module) and any(
        eqx.is_inexact_array(leaf) for leaf in jax.tree_util.tree_leaves(function)
    )


def hessian_vector_system(
    lag_flat: FlatLagrangian, q: jax.Array, v: jax.Array, t: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """(M, ∂L/∂q − (∂²L/∂q̇∂q) q̇ − ∂²L/∂q̇∂t) of `lag_flat(q, v, t)` on flat
    arrays, by one gradient and n + 1 Hessian–vector products in one batched pass."""
    n = q.shape[0]
    gradient = jax.grad(lag_flat, argnums=(0, 1))
    # Rows 0..n-1: along (0, e_k, 0), the columns of M; row n: along (q̇, 0, 1).
    tangents_q = jnp.concatenate([jnp.zeros((n, n), q.dtype), v[None]], axis=0)
    tangents_v = jnp.concatenate([jnp.eye(n, dtype=q.dtype), jnp.zeros((1, n))], axis=0)
    tangents_t = jnp.zeros(n + 1, t.dtype).at[n].set(1)

    def along(dq, dv, dt):
        return jax.jvp(gradient, (q, v, t), (dq, dv, dt))

    (force, _), (_, second) = jax.vmap(along)(tangents_q, tangents_v, tangents_t)
    # The primal gradient does not depend on the tangent: vmap computes it once.
    return second[:n], force[0] - second[n]


@eqx.filter_jit
def network_euler_lagrange_acceleration(
    lagrangian: Callable[[Any, Any, Any, Any], jax.Array],
    q: Any,
    qdot: Any,
    t: Any,
    args: Any,
    generalized_force: Any = None,
    *,
    check: bool | str = True,
) -> Any:
    """q̈ from the Euler–Lagrange equations by Hessian–vector products.

    Same arguments, `check` semantics and result as `euler_lagrange_acceleration`
    (q and q̇ any matching pytrees, `generalized_force` None or like q); only the
    derivation differs.
    """
    lag_flat, q_flat, v_flat, t, unravel = flat_lagrangian(lagrangian, q, qdot, t, args)
    mass, rhs = hessian_vector_system(lag_flat, q_flat, v_flat, t)
    if generalized_force is not None:
        rhs = rhs + ravel_pytree(generalized_force)[0]
    # LU with partial pivoting: the network's matrix products dominate the cost, and
    # pivoting solves any nonsingular M (a learned one need not be definite).
    qddot, singular = solve_dense(mass, rhs)
    return unravel(apply_singular_check(qddot, singular, check))
