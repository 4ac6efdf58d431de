r"""Small oscillations about equilibrium: equilibria, T and V matrices, normal modes.

Near an equilibrium $q_0$ ($\partial V/\partial q = 0$) the Lagrangian is, to second
order, $L \approx \tfrac12 \dot\eta^T T \dot\eta - \tfrac12 \eta^T V \eta$ with
$T = \partial^2 L/\partial\dot q^2$ and $V = -\partial^2 L/\partial q^2$, both at
$(q_0, \dot q = 0)$. Normal modes solve the generalized symmetric eigenproblem

$$ V a_k = \omega_k^2\, T a_k, \qquad A^T T A = 1 $$

(the secular equation $|V - \omega^2 T| = 0$). It is solved by the Cholesky factor
$T = C C^T$: $C^{-1} V C^{-T} u = \omega^2 u$, $a = C^{-T} u$.

References: the course text §5 (eq. 5.12–5.25, CO₂ in §5.3), Goldstein,
*Classical Mechanics* §6.2.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import optimistix as optx
from jax.flatten_util import ravel_pytree

from .lagrangian import Lagrangian


def _potential_gradient(lag: Lagrangian, q: Any, t: Any, args: Any) -> Any:
    """∂V/∂q = −∂L/∂q at q̇ = 0."""
    zero_velocity = jax.tree_util.tree_map(jnp.zeros_like, q)
    gradient = jax.grad(lag, argnums=0)(q, zero_velocity, t, args)
    return jax.tree_util.tree_map(jnp.negative, gradient)


def equilibrium(
    lag: Lagrangian,
    q_guess: Any,
    args: Any = None,
    *,
    t: Any = 0.0,
    rtol: float = 1e-12,
    atol: float = 1e-12,
    max_steps: int = 256,
) -> Any:
    """A configuration with ∂V/∂q = 0, found by Newton's method from `q_guess`.

    Any stationary point of V can be returned (minimum, saddle or maximum): the one
    Newton's method reaches from the guess. Classify it with `normal_modes`.
    Raises if Newton's method does not converge.
    """
    q_flat, unravel = ravel_pytree(q_guess)

    def residual(x, _):
        return ravel_pytree(_potential_gradient(lag, unravel(x), t, args))[0]

    solution = optx.root_find(
        residual, optx.Newton(rtol=rtol, atol=atol), q_flat, max_steps=max_steps
    )
    return unravel(solution.value)


def stiffness_matrices(
    lag: Lagrangian, q_eq: Any, args: Any = None, *, t: Any = 0.0
) -> tuple[jax.Array, jax.Array]:
    """The (T, V) matrices of the small-oscillation problem at `q_eq` (flat coordinates)."""
    q_flat, unravel = ravel_pytree(q_eq)
    zero_velocity = jnp.zeros_like(q_flat)
    kinetic = lag.mass_matrix(q_eq, unravel(zero_velocity), t, args)
    potential = -jax.hessian(
        lambda x: lag(unravel(x), unravel(zero_velocity), t, args)
    )(q_flat)
    return kinetic, potential


def normal_modes(
    lag: Lagrangian, q_eq: Any, args: Any = None, *, t: Any = 0.0
) -> tuple[jax.Array, jax.Array]:
    """Normal-mode frequencies and shapes about the equilibrium `q_eq`.

    **Returns:** `(omegas, modes)`: `omegas` ascending, shape (n,); `modes` (n, n) with
    mode k in column k, in the raveled coordinates of q, normalised so that
    `modes.T @ T @ modes = I`. A negative entry of `omegas` marks an unstable
    direction: it is −γ where γ is the growth rate, e^{γt}, of that mode (ω² < 0).

    The expansion assumes no terms linear in q̇ (no gyroscopic or magnetic forces)
    and that `q_eq` is an equilibrium (see `equilibrium`).
    """
    kinetic, potential = stiffness_matrices(lag, q_eq, args, t=t)
    cholesky = eqx.error_if(
        jnp.linalg.cholesky(kinetic),
        ~jnp.all(jnp.isfinite(jnp.linalg.cholesky(kinetic))),
        "The kinetic matrix T = ∂²L/∂q̇∂q̇ at q_eq is not positive definite, so the "
        "small oscillations have no normal modes there.",
    )
    half = jsl.solve_triangular(cholesky, potential, lower=True)
    reduced = jsl.solve_triangular(cholesky, half.T, lower=True)
    # Symmetrise: the two triangular solves leave round-off asymmetry.
    squared, vectors = jnp.linalg.eigh(0.5 * (reduced + reduced.T))
    modes = jsl.solve_triangular(cholesky.T, vectors, lower=False)
    omegas = jnp.sign(squared) * jnp.sqrt(jnp.abs(squared))
    return omegas, modes
