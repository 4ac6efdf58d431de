r"""The Hénon–Heiles Hamiltonian, the classic test of the phase-space tools.

$$ H = \tfrac12(p_x^2 + p_y^2) + \tfrac12(x^2 + y^2) + x^2 y - \tfrac13 y^3, $$

a star's motion in a galactic potential truncated at cubic order (Hénon & Heiles
1964). Orbits are bounded for E < 1/6 (the saddle energy). The surface of section
$x = 0$, $p_x > 0$ shows almost only invariant curves at E = 1/12, a mixed phase
space at E = 1/8 and a mostly chaotic one at E = 1/6.

**References:** Hénon & Heiles, Astron. J. 69, 73 (1964); Lichtenberg & Lieberman,
*Regular and Chaotic Dynamics*, 2nd ed., §1.4a.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from lagjax.mechanics.hamiltonian import SeparableHamiltonian
from lagjax.phase_space.energy_shell import states_on_energy_shell

ESCAPE_ENERGY = 1 / 6


def henon_heiles_potential(q: jax.Array) -> jax.Array:
    x, y = q[0], q[1]
    return 0.5 * (x**2 + y**2) + x**2 * y - y**3 / 3


def henon_heiles_kinetic(p: jax.Array) -> jax.Array:
    return 0.5 * (p[0] ** 2 + p[1] ** 2)


def henon_heiles() -> SeparableHamiltonian:
    """H = ½|p|² + V(x, y) with q = (x, y) as an array.

    Built from module-level functions, so every call gives an equal system and
    compiled runs are reused.
    """
    return SeparableHamiltonian(henon_heiles_kinetic, henon_heiles_potential)


def section_plane(q: Any, p: Any) -> jax.Array:
    """The surface x = 0 (crossed upwards: p_x > 0)."""
    del p
    return q[0]


def henon_heiles_section_states(
    energy: float, y_values: Any, py_values: Any
) -> tuple[np.ndarray, np.ndarray]:
    """States on x = 0 at energy E from a (y, p_y) grid, with p_x ≥ 0 from H = E.

    Grid points outside the energy shell are dropped.
    """
    y, py = np.meshgrid(np.asarray(y_values), np.asarray(py_values), indexing="ij")
    y, py = y.ravel(), py.ravel()
    q = np.stack([np.zeros_like(y), y], axis=1)
    p = np.stack([np.zeros_like(y), py], axis=1)
    return states_on_energy_shell(
        henon_heiles(), energy, (jnp.asarray(q), jnp.asarray(p)), solve_for=0
    )
