r"""Small oscillations on a constraint surface: the reduced M, G, K and a tangent basis.

With holonomic constraints $g(q) = 0$ (k of them, $G_c = \partial g/\partial q$ of
full row rank) the small motions about an equilibrium $q_0$ on the surface are
$\eta = N s$, $N$ an orthonormal basis of $\ker G_c$. The constraint force
$G_c^T\lambda$ that holds $q_0$ in place ($\lambda$ the Lagrange multipliers there)
changes direction as the point moves along the curved surface; to second order this
is the Hessian of $\lambda\cdot g$ (the "geometric stiffness"), so the effective
Lagrangian is $L + \lambda\cdot g$ and

$$ M_r = N^TMN, \quad G_r = N^TGN, \quad
   K_r = N^T\Bigl(K - \sum_i\lambda_i\,\nabla^2g_i\Bigr)N . $$

A Cartesian pendulum hanging from its rod: $K = 0$, $\lambda = -mg$,
$\nabla^2 g = (1 - \hat r\hat r^T)/l$, so $K_r = mg/l$ and $\omega = \sqrt{g/l}$.
Mode shapes $a = N a_r$ keep $a^TMa = a_r^TM_ra_r$.

References: Meirovitch, *Methods of Analytical Dynamics* §6.6 (constrained
systems); Nocedal & Wright, *Numerical Optimization* §12.4 (the Hessian of the
Lagrangian on the tangent space).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax.mechanics.lagrangian import Lagrangian


def null_space(matrix: jax.Array, what: str) -> jax.Array:
    """Orthonormal basis of ker(matrix) (columns), with a run-time full-row-rank check."""
    rows, columns = matrix.shape
    if rows == 0:
        return jnp.eye(columns, dtype=matrix.dtype)
    _, singular, vh = jnp.linalg.svd(matrix, full_matrices=True)
    threshold = 64 * columns * jnp.finfo(matrix.dtype).eps * singular[0]
    return eqx.error_if(
        vh[rows:].T,
        singular[-1] <= threshold,
        f"{what} is rank-deficient at the operating point: redundant or degenerate "
        "constraints leave the constraint manifold undefined there.",
    )


def reduce_to_constraint_surface(
    lag: Lagrangian,
    q_eq: Any,
    args: Any,
    t: Any,
    matrices: tuple[jax.Array, jax.Array, jax.Array],
) -> tuple[tuple[jax.Array, jax.Array, jax.Array], jax.Array, jax.Array]:
    """((M_r, K_r, G_r), N, g(q_eq)) from the full (M, K, G) of a constrained `lag`."""
    constraints = lag.constraints
    assert constraints is not None
    if constraints.velocity is not None:
        raise ValueError(
            "normal_modes reduces holonomic constraints only; this Lagrangian has "
            "velocity (nonholonomic) constraints, whose small motions are not "
            "those of a reduced Lagrangian. Use lj.linearize(lag, (q_eq, qdot_eq), "
            "args), which linearizes on the constraint manifold."
        )
    q_flat, unravel = ravel_pytree(q_eq)

    def surface(x):
        return constraints.position_residual(unravel(x), t, args)

    basis = null_space(jax.jacfwd(surface)(q_flat), "∂g/∂q")
    zero_velocity = unravel(jnp.zeros_like(q_flat))
    multipliers = lag.multipliers(q_eq, zero_velocity, t, args)
    curvature = jax.hessian(lambda x: multipliers @ surface(x))(q_flat)
    kinetic, potential, gyro = matrices
    reduced = (
        basis.T @ kinetic @ basis,
        basis.T @ (potential - curvature) @ basis,
        basis.T @ gyro @ basis,
    )
    return reduced, basis, surface(q_flat)
