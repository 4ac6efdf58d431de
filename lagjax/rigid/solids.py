r"""Inertia tensors of uniform standard solids about their centre of mass.

Every body is placed with its symmetry axis (or its edges) along the coordinate
axes, its centre of mass at the origin, so each tensor is diagonal. The moment
about another point follows from `parallel_axis`; e.g. a solid cone about its apex
is `parallel_axis(solid_cone_inertia(M, R, h), M, [0, 0, cone_apex_distance(h)])`.

| body | $I_x = I_y$ | $I_z$ (axis) |
|---|---|---|
| thin rod, length $\ell$ along z | $M\ell^2/12$ | 0 |
| thin disc, radius $R$, normal z | $MR^2/4$ | $MR^2/2$ |
| solid sphere | $2MR^2/5$ | $2MR^2/5$ |
| thin spherical shell | $2MR^2/3$ | $2MR^2/3$ |
| solid cylinder, radius $R$, height $h$ | $M(3R^2 + h^2)/12$ | $MR^2/2$ |
| solid cone, base radius $R$, height $h$ | $3M(4R^2 + h^2)/80$ | $3MR^2/10$ |

and a box with edges $a, b, c$ along x, y, z:
$\mathrm{diag}(b^2 + c^2,\ a^2 + c^2,\ a^2 + b^2)\,M/12$.

References: Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §5.3 and
back endpapers; the course text §4.4–4.6 (definition and the axis theorems).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def _diagonal(transverse: jax.Array, axial: jax.Array) -> jax.Array:
    transverse, axial = jnp.broadcast_arrays(transverse, axial)
    return jnp.diag(jnp.stack([transverse, transverse, axial]))


def thin_rod_inertia(mass: jax.Array, length: jax.Array) -> jax.Array:
    """A thin uniform rod along z; zero moment about its own axis."""
    return _diagonal(mass * length**2 / 12, 0.0 * mass)


def thin_disc_inertia(mass: jax.Array, radius: jax.Array) -> jax.Array:
    """A thin uniform disc in the xy plane (a lamina: I_z = I_x + I_y)."""
    return _diagonal(mass * radius**2 / 4, mass * radius**2 / 2)


def solid_sphere_inertia(mass: jax.Array, radius: jax.Array) -> jax.Array:
    """A uniform solid ball: a spherical top."""
    return _diagonal(2 * mass * radius**2 / 5, 2 * mass * radius**2 / 5)


def spherical_shell_inertia(mass: jax.Array, radius: jax.Array) -> jax.Array:
    """A thin uniform spherical shell."""
    return _diagonal(2 * mass * radius**2 / 3, 2 * mass * radius**2 / 3)


def box_inertia(
    mass: jax.Array, edge_x: jax.Array, edge_y: jax.Array, edge_z: jax.Array
) -> jax.Array:
    """A uniform rectangular box with edges along the axes."""
    a2, b2, c2 = edge_x**2, edge_y**2, edge_z**2
    moments = jnp.stack(jnp.broadcast_arrays(b2 + c2, a2 + c2, a2 + b2))
    return jnp.diag(mass * moments / 12)


def solid_cylinder_inertia(
    mass: jax.Array, radius: jax.Array, height: jax.Array
) -> jax.Array:
    """A uniform solid circular cylinder with its axis along z."""
    return _diagonal(mass * (3 * radius**2 + height**2) / 12, mass * radius**2 / 2)


def solid_cone_inertia(
    mass: jax.Array, radius: jax.Array, height: jax.Array
) -> jax.Array:
    """A uniform solid right circular cone, axis along z, about its centre of mass."""
    transverse = 3 * mass * (4 * radius**2 + height**2) / 80
    return _diagonal(transverse, 3 * mass * radius**2 / 10)


def cone_apex_distance(height: jax.Array) -> jax.Array:
    """Distance from a solid cone's apex to its centre of mass: 3h/4."""
    return 0.75 * jnp.asarray(height)
