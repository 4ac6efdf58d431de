r"""Initial states on an energy shell: fill in one velocity or momentum from H = E.

A surface of section of a two-degree-of-freedom system is drawn at fixed energy: the
initial states are a grid in the section's own coordinates, e.g. $(y, p_y)$ on
$x = 0$ for Hénon–Heiles, and the remaining momentum (here $p_x > 0$) follows from
$H(q, p) = E$. It is the non-negative root of one scalar equation, found by Newton's
method started from the unit-mass guess $\sqrt{2(E - H|_{p_i = 0})}$ (exact when H
is $\tfrac12 p_i^2 + \ldots$); states whose energy at $p_i = 0$ already exceeds E
are outside the shell and are dropped. For a Lagrangian the energy is the Jacobi
integral $h(q, \dot q)$ and the component filled in is a velocity.

**References:** Hénon & Heiles, Astron. J. 69, 73 (1964) (their sections' initial
conditions); Lichtenberg & Lieberman, *Regular and Chaotic Dynamics*, 2nd ed., §1.4.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from lagjax.phase_space.flow import resolve_system

_NEWTON_ITERATIONS = 30


def _energy_function(system: Any, args: Any):
    mechanical, args = resolve_system(system, args)
    return lambda q, second: mechanical.state_energy(q, second, 0.0, args)


def states_on_energy_shell(
    system: Any,
    energy: float,
    y0s: tuple[Any, Any],
    solve_for: int,
    *,
    args: Any = None,
) -> tuple[Any, Any]:
    """The members of the batch `y0s` moved onto the shell H = `energy`.

    **Arguments:**
    - `y0s`: a batch `(q0s, p0s)` (or `(q0s, qdot0s)` for a Lagrangian) with a
      leading batch axis; component `solve_for` of the flattened second member is
      ignored and replaced by the non-negative root of H = E.
    - `solve_for`: the index of that component in the flattened p (or q̇).

    **Returns:** the batch restricted to the states that lie on the shell (a
    concrete, smaller batch: call it outside `jit`).
    """
    energy_of = _energy_function(system, args)
    q0s, seconds = y0s
    first_second = jax.tree_util.tree_map(lambda x: jnp.asarray(x)[0], seconds)
    flat, unravel = ravel_pytree(first_second)
    if not 0 <= solve_for < flat.shape[0]:
        raise ValueError(
            f"solve_for = {solve_for} is not a component of the flattened momentum "
            f"(it has {flat.shape[0]})."
        )

    def fill(q, second):
        base = ravel_pytree(second)[0].at[solve_for].set(0.0)

        def excess(value):
            return energy_of(q, unravel(base.at[solve_for].set(value))) - energy

        def newton(_, value):
            return value - excess(value) / jax.grad(excess)(value)

        start = jnp.sqrt(jnp.maximum(-2 * excess(0.0), 0.0))
        root = jax.lax.fori_loop(0, _NEWTON_ITERATIONS, newton, start + 1e-3)
        inside = excess(0.0) <= 0
        return unravel(base.at[solve_for].set(root)), inside

    filled, inside = jax.jit(jax.vmap(fill))(q0s, seconds)
    keep = np.asarray(inside)
    return jax.tree_util.tree_map(lambda x: np.asarray(x)[keep], (q0s, filled))
