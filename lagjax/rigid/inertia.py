r"""The inertia tensor: from point masses, moved between axes, diagonalised.

For masses $m_i$ at positions $\mathbf r_i$ about a reference point,

$$ I_{\alpha\beta} = \sum_i m_i \left(r_i^2\,\delta_{\alpha\beta}
   - r_{i\alpha} r_{i\beta}\right) \qquad \text{(course text eq. 4.28)}, $$

so that $\mathbf L = \mathbf I\,\boldsymbol\omega$ and
$T = \tfrac12\boldsymbol\omega^T\mathbf I\boldsymbol\omega$. The tensor is real and
symmetric, so an orthogonal change of axes diagonalises it (course text §4.5): the
eigenvalues are the *principal moments* $I_1, I_2, I_3$, the eigenvectors the
*principal axes*. By the degeneracy of the moments a body is an *asymmetric*
($I_1 \ne I_2 \ne I_3$), *symmetric* (two equal) or *spherical* (all equal) top.

Moving the reference point from the centre of mass by $\mathbf d$ adds the tensor of
the total mass concentrated at the centre of mass (parallel-axis theorem, course text
§4.6.2); for a plane lamina the moment about the normal is the sum of the two
in-plane moments (perpendicular-axis theorem, course text §4.6.1).

References: the course text §4.4–4.6; Goldstein, Poole & Safko, *Classical
Mechanics*, 3rd ed., §5.3–5.4; Landau & Lifshitz, *Mechanics*, §32.
"""

from __future__ import annotations

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

TopKind = Literal["asymmetric", "symmetric", "spherical"]


def check_moments(moments: jax.Array, what: str = "principal moments") -> jax.Array:
    """`moments`, after checking they are finite and positive.

    Concrete values are checked at once (`ValueError` naming them); traced ones
    (a body built inside `jit`/`vmap`) at run time (`eqx.error_if`). A zero, negative,
    infinite or NaN moment is no rigid body: ω = Π/I would be infinite, negative
    kinetic energy possible, or every result NaN.
    """
    remedy = "give finite positive moments of inertia, e.g. (1.0, 2.0, 3.0)"
    if isinstance(moments, Tracer):
        bad = ~jnp.all(jnp.isfinite(moments) & (moments > 0))
        return eqx.error_if(
            moments, bad, f"{what} must be finite and positive: {remedy}"
        )
    values = np.asarray(moments)
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{what} {values} are not all finite: {remedy}")
    if not np.all(values > 0):
        raise ValueError(f"{what} {values} must all be positive: {remedy}")
    return moments


def _check_masses(masses: jax.Array) -> None:
    if isinstance(masses, Tracer):
        return
    values = np.asarray(masses)
    if not (np.all(np.isfinite(values)) and np.all(values > 0)):
        raise ValueError(f"point masses must be finite and positive, got {values}")


def point_mass_inertia(masses: jax.Array, positions: jax.Array) -> jax.Array:
    r"""Inertia tensor of point masses about the origin (course text eq. 4.27).

    **Arguments:**
    - `masses`: shape `(n,)`.
    - `positions`: shape `(n, 3)`, relative to the reference point.

    **Returns:** the symmetric `(3, 3)` tensor
    $\sum_i m_i (r_i^2\,\mathbb 1 - \mathbf r_i \mathbf r_i^T)$.
    """
    masses = jnp.asarray(masses)
    positions = jnp.asarray(positions)
    if positions.ndim != 2 or positions.shape[-1] != 3:
        raise ValueError(f"positions must have shape (n, 3), got {positions.shape}")
    if masses.shape != positions.shape[:1]:
        raise ValueError(
            f"masses must have shape ({positions.shape[0]},) to match positions, "
            f"got {masses.shape}"
        )
    _check_masses(masses)
    squared_radii = jnp.sum(positions**2, axis=-1)
    isotropic = jnp.sum(masses * squared_radii) * jnp.eye(3, dtype=positions.dtype)
    return isotropic - jnp.einsum("i,ia,ib->ab", masses, positions, positions)


def centre_of_mass(masses: jax.Array, positions: jax.Array) -> jax.Array:
    """Mass-weighted mean position, shape `(3,)`."""
    masses = jnp.asarray(masses)
    return jnp.einsum("i,ia->a", masses, jnp.asarray(positions)) / jnp.sum(masses)


def parallel_axis(
    inertia_about_centre: jax.Array, mass: jax.Array, displacement: jax.Array
) -> jax.Array:
    r"""The tensor about a point displaced by $\mathbf d$ from the centre of mass.

    $$ \mathbf I_O = \mathbf I_{CM} + M\left(d^2\,\mathbb 1
       - \mathbf d\,\mathbf d^T\right). $$

    Its moment about an axis $\hat n$ is $I_{CM} + M d^2 \sin^2\theta$, the course
    text's §4.6.2 form. The input must be about the centre of mass: the theorem does
    not hold between two arbitrary points.
    """
    d = jnp.asarray(displacement)
    shift = mass * (jnp.dot(d, d) * jnp.eye(3, dtype=d.dtype) - jnp.outer(d, d))
    return jnp.asarray(inertia_about_centre) + shift


def perpendicular_axis(
    inertia_first_in_plane: jax.Array, inertia_second_in_plane: jax.Array
) -> jax.Array:
    r"""Moment of a plane lamina about its normal: $I_z = I_x + I_y$.

    Holds only for a flat body (all mass in the plane $z = 0$), with $x, y$ two
    perpendicular in-plane axes meeting the normal (course text §4.6.1).
    """
    return jnp.asarray(inertia_first_in_plane) + jnp.asarray(inertia_second_in_plane)


def principal_axes(inertia: jax.Array) -> tuple[jax.Array, jax.Array]:
    r"""Principal moments and axes: $\mathbf I = E\,\mathrm{diag}(I_1, I_2, I_3)\,E^T$.

    **Returns:** `(moments, axes)`: moments in ascending order, and `axes` a proper
    rotation matrix (det +1) whose *columns* are the principal axes. `axes` is then
    the body-to-reference rotation of a body frame along the principal axes.

    For a symmetric or spherical top the axes within a degenerate eigenspace are any
    orthonormal pair (or triple) — every such choice diagonalises the tensor, as
    the physics allows. Derivatives with respect to an exactly degenerate tensor are
    undefined (the eigenvectors are not).
    """
    inertia = jnp.asarray(inertia)
    if inertia.shape != (3, 3):
        raise ValueError(f"an inertia tensor has shape (3, 3), got {inertia.shape}")
    # eigh reads one triangle; symmetrise so that round-off asymmetry cannot bias it.
    moments, axes = jnp.linalg.eigh(0.5 * (inertia + inertia.T))
    # Flip the last axis of a left-handed triple so the frame is a rotation.
    handedness = jnp.sign(jnp.linalg.det(axes))
    return moments, axes.at[:, 2].multiply(handedness)


def top_kind(moments: jax.Array, rtol: float = 1e-9) -> TopKind:
    """Classify concrete principal moments as an asymmetric, symmetric or spherical top.

    Two moments count as equal within `rtol` of the largest. Needs concrete values
    (it returns a Python string), so call it outside `jit`.
    """
    try:
        values = np.sort(np.asarray(moments, dtype=float).reshape(-1))
    except jax.errors.TracerArrayConversionError as error:
        raise ValueError(
            "top_kind needs concrete moments (it returns a string); call it outside jit"
        ) from error
    if values.shape != (3,):
        raise ValueError(f"expected three principal moments, got {values.shape[0]}")
    tolerance = rtol * abs(values[-1])
    equal_pairs = int(values[1] - values[0] <= tolerance) + int(
        values[2] - values[1] <= tolerance
    )
    return ("asymmetric", "symmetric", "spherical")[equal_pairs]
