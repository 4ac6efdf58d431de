r"""Relative equilibria: points at rest in a rotating (or otherwise moving) frame.

A particle at rest in a frame turning at $\boldsymbol\Omega$ is in a *relative*
equilibrium: in inertial space it moves on a circle. In the frame's coordinates its
Lagrangian $L = \tfrac12 m|\dot{\mathbf r} + \boldsymbol\Omega\times\mathbf r|^2 -
V(\mathbf r)$ gives, at $\dot{\mathbf r} = 0$, the effective potential

$$ V_{\rm eff}(\mathbf r) = -L(\mathbf r, 0)
   = V(\mathbf r) - \tfrac12 m|\boldsymbol\Omega\times\mathbf r|^2 , $$

and the relative equilibria are its stationary points, $\partial V_{\rm eff}/\partial
q = 0$ (the Coriolis force vanishes at rest). The same holds for any Lagrangian: a
point with $\ddot q(q, \dot q = 0) = 0$ is at rest for all time. Here the
condition is solved as $\ddot q(q, 0) = 0$ by Newton's method (optimistix), which
also covers generalized forces, an explicit time dependence at the given t, and
— by least squares on $(\ddot q, g(q))$ — holonomic constraints. A Hamiltonian's
equilibrium is a zero of its vector field in $(q, p)$; in a rotating frame $p \ne 0$
there ($\mathbf p = m\,\boldsymbol\Omega\times\mathbf r$).

The five Lagrange points of the restricted three-body problem are the classic
example (Murray & Dermott, *Solar System Dynamics* §3.5–3.8); their stability,
Routh's criterion, comes from `normal_modes` or `linearize`.

References: the course text §1.3 (centrifugal potential); Landau & Lifshitz,
*Mechanics* §39; Marsden & Ratiu, *Introduction to Mechanics and Symmetry* §4.3
(relative equilibria).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.flatten_util import ravel_pytree

from lagjax._core.system import AbstractSystem
from lagjax.mechanics.hamiltonian import AbstractHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.mechanics.stability import is_concrete


class _Solved(NamedTuple):
    value: jax.Array
    converged: jax.Array
    residual: jax.Array
    steps: jax.Array


def _residual_function(system, unravel, t, args):
    """x ↦ the rates that vanish at rest: q̈(q, 0) (and g(q)), or (q̇, ṗ)."""
    if isinstance(system, AbstractHamiltonian):

        def rates(x, _):
            q, p = unravel(x)
            return ravel_pytree(system.vector_field(q, p, t, args))[0]

        return rates

    def accelerations(x, _):
        q = unravel(x)
        zero_velocity = jax.tree_util.tree_map(jnp.zeros_like, q)
        rows = [ravel_pytree(system.acceleration(q, zero_velocity, t, args))[0]]
        if system.constraints is not None:
            rows.append(system.constraints.position_residual(q, t, args))
        return jnp.concatenate(rows)

    return accelerations


# Compiled as a whole: Newton's steps through nested derivatives dispatched op by
# op cost seconds.
@eqx.filter_jit
def _solve(system, guess, t, args, rtol, atol, max_steps) -> _Solved:
    start, unravel = ravel_pytree(guess)
    residual = _residual_function(system, unravel, t, args)
    constrained = isinstance(system, Lagrangian) and system.constraints is not None
    if constrained:
        solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
        solution = optx.least_squares(
            residual, solver, start, max_steps=max_steps, throw=False
        )
    else:
        solution = optx.root_find(
            residual,
            optx.Newton(rtol=rtol, atol=atol),
            start,
            max_steps=max_steps,
            throw=False,
        )
    return _Solved(
        solution.value,
        solution.result == optx.RESULTS.successful,
        residual(solution.value, None),
        solution.stats["num_steps"],
    )


def _raise_unless_converged(solved: _Solved, what: str) -> None:
    if not is_concrete(solved.converged) or bool(solved.converged):
        return
    raise ValueError(
        f"relative_equilibrium did not converge from this guess: after "
        f"{int(solved.steps)} Newton steps the {what} is still "
        f"{np.array2string(np.asarray(solved.residual), precision=4)}. Start closer "
        "to an equilibrium, or check that one exists (e.g. a free particle has none)."
    )


def relative_equilibrium(
    system: Any,
    guess: Any,
    args: Any = None,
    *,
    t: Any = 0.0,
    rtol: float = 1e-12,
    atol: float = 1e-12,
    max_steps: int = 256,
) -> Any:
    r"""A state at rest (in the system's own, possibly rotating, coordinates).

    **Arguments:**
    - `system`: a `Lagrangian` (constrained or not), a Hamiltonian, or a scene
      (whose `args` default to it).
    - `guess`: for a Lagrangian the configuration q (q̇ = 0 is implied); for a
      Hamiltonian the state `(q, p)`.
    - `rtol`, `atol`, `max_steps`: of optimistix's Newton (Levenberg–Marquardt
      with constraints).

    **Returns:** q (Lagrangian) or `(q, p)` (Hamiltonian), the root Newton's
    method reaches from the guess — a minimum, saddle or maximum of $V_{\rm eff}$;
    classify it with `normal_modes` or `linearize`. Raises a `ValueError` with the
    remaining residual when Newton's method does not converge (outside `jax.jit`).
    """
    if isinstance(system, AbstractSystem):
        system, args = system.resolve(args)  # a scene: its system and itself
    if isinstance(system, AbstractHamiltonian):
        if not (isinstance(guess, (tuple, list)) and len(guess) == 2):
            raise ValueError(
                "for a Hamiltonian the guess is the state (q, p): in a rotating "
                "frame p is not zero at rest"
            )
        guess, what = tuple(guess), "vector field (q̇, ṗ)"
    elif isinstance(system, Lagrangian):
        what = "acceleration q̈(q, q̇ = 0)"
    else:
        raise TypeError(
            "relative_equilibrium needs a lagjax Lagrangian, Hamiltonian or scene; "
            f"got {type(system).__name__}"
        )
    solved = _solve(system, guess, t, args, rtol, atol, max_steps)
    _raise_unless_converged(solved, what)
    unravel = ravel_pytree(guess)[1]
    value = unravel(solved.value)
    if not is_concrete(solved.converged):
        value = eqx.error_if(
            value, ~solved.converged, "relative_equilibrium did not converge"
        )
    return value
