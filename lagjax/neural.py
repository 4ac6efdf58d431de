r"""Euler–Lagrange accelerations of a network-sized Lagrangian, for training.

`Lagrangian.acceleration` re-expresses L as scalar arithmetic for up to six
coordinates, which makes closed-form Lagrangians as fast as hand-written equations
but pushes every scalar tangent through the whole of a neural network separately:
for an MLP the compilation of a training step's gradient grows from seconds to a
minute. A network's cost is its matrix products, and the least work the equations
need is one gradient of L and n + 1 Hessian–vector products, batched here in one
forward-over-reverse pass:

$$ M\ddot q = \frac{\partial L}{\partial q}
   - \frac{\partial^2 L}{\partial\dot q\,\partial q}\dot q,
   \qquad M = \frac{\partial^2 L}{\partial\dot q\,\partial\dot q}, $$

with the columns of M the derivative of ∇L along $(0, e_k)$ and the transport term
its derivative along $(\dot q, 0)$. Compared with the published Lagrangian neural
network formula (Hessian, Jacobian of the Jacobian, pseudo-inverse) this is 1.5×
faster per training step on CPU (`benchmarks/lnn_training.py`).

References: M. Cranmer et al., "Lagrangian Neural Networks" (2020),
arXiv:2003.04630, eq. 6; M. Lutter, C. Ritter, J. Peters, "Deep Lagrangian
Networks" (ICLR 2019).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp


def network_acceleration(
    lagrangian: Callable[[jax.Array, jax.Array], jax.Array],
    q: jax.Array,
    qdot: jax.Array,
) -> jax.Array:
    """q̈ of an autonomous `lagrangian(q, qdot)` of 1-D arrays, for a network L.

    No conditioning test is made: a singular mass matrix gives inf/NaN (from the
    LU solve), which a training loss then shows. Use `lj.Lagrangian(L).acceleration`
    for closed-form Lagrangians, forces, time dependence or pytree coordinates.
    """
    q, qdot = jnp.asarray(q), jnp.asarray(qdot)
    if q.ndim != 1 or q.shape != qdot.shape:
        raise ValueError(
            "network_acceleration takes q and qdot as 1-D arrays of one length; got "
            f"shapes {q.shape} and {qdot.shape}. vmap it over a batch of states."
        )
    n = q.shape[0]
    gradient = jax.grad(lagrangian, argnums=(0, 1))
    tangents_q = jnp.concatenate([jnp.zeros((n, n), q.dtype), qdot[None]], axis=0)
    tangents_v = jnp.concatenate([jnp.eye(n, dtype=q.dtype), jnp.zeros((1, n))], axis=0)

    def along(dq, dv):
        return jax.jvp(gradient, (q, qdot), (dq, dv))

    (force, _), (_, second) = jax.vmap(along)(tangents_q, tangents_v)
    mass, transport = second[:n], second[n]
    return jnp.linalg.solve(mass, force[0] - transport)
