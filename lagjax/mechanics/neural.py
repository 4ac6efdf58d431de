r"""Euler–Lagrange accelerations of a network-sized Lagrangian, for training.

`network_acceleration(net, q, qdot)` is the q̈ of an autonomous L(q, q̇) on 1-D
arrays by one gradient and n + 1 Hessian–vector products in one batched
forward-over-reverse pass (`lagjax.mechanics.network_formulation`, which has the
math), solved by LU without a conditioning test: the bare prediction of a
Lagrangian neural network's training loss. `lj.Lagrangian(net).acceleration` uses
the same formulation for a network L (an equinox Module with array leaves) and adds
time dependence, `args`, forces, constraints, pytree coordinates and the
singular-matrix check.

On one LNN training step (`benchmarks/lnn_training.py`: 256 double-pendulum states,
4-128-128-1 softplus MLP, CPU, float64) this is about 1.5× faster than the
published formula (`jax.hessian`, Jacobian of the Jacobian, pseudo-inverse). The
benchmark counts the network's matrix products: the Hessian of that MLP derived by
hand reaches 1.9×, and no exact formulation can reach 5× there.

References: M. Cranmer et al., "Lagrangian Neural Networks" (2020),
arXiv:2003.04630, eq. 6; M. Lutter, C. Ritter, J. Peters, "Deep Lagrangian
Networks" (ICLR 2019).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from lagjax.mechanics.network_formulation import hessian_vector_system


def network_acceleration(
    lagrangian: Callable[[jax.Array, jax.Array], jax.Array],
    q: jax.Array,
    qdot: jax.Array,
) -> jax.Array:
    """q̈ of an autonomous `lagrangian(q, qdot)` of 1-D arrays, for a network L.

    No conditioning test is made: a singular mass matrix gives inf/NaN (from the
    LU solve), which a training loss then shows. Use `lj.Lagrangian(L).acceleration`
    for forces, time dependence, pytree coordinates or a singularity check.
    """
    q, qdot = jnp.asarray(q), jnp.asarray(qdot)
    if q.ndim != 1 or q.shape != qdot.shape:
        raise ValueError(
            "network_acceleration takes q and qdot as 1-D arrays of one length; got "
            f"shapes {q.shape} and {qdot.shape}. vmap it over a batch of states."
        )
    mass, rhs = hessian_vector_system(
        lambda a, b, _t: lagrangian(a, b), q, qdot, jnp.zeros((), q.dtype)
    )
    return jnp.linalg.solve(mass, rhs)
