r"""Unit quaternions as rotations: algebra, rotation matrices, angular velocity.

A quaternion is an array $(w, x, y, z)$, scalar first. A unit quaternion $q$
represents the rotation that carries body components to space components,

$$ \mathbf v_{\text{space}} = R(q)\,\mathbf v_{\text{body}}, \qquad
   q = \left(\cos\tfrac\alpha2,\ \hat{\mathbf n}\sin\tfrac\alpha2\right)
   \ \text{for a turn by } \alpha \text{ about } \hat{\mathbf n}, $$

so $R(q)$ is the transpose of the course text's space-to-body matrix $A$
(eq. 4.19–4.20), and $q$ and $-q$ are the same rotation. Composition is the Hamilton
product: $R(p \otimes q) = R(p)\,R(q)$. The orientation moves as

$$ \dot q = \tfrac12\, q \otimes (0, \boldsymbol\omega_{\text{body}})
          = \tfrac12\, (0, \boldsymbol\omega_{\text{space}}) \otimes q, $$

which keeps $|q|$ constant: unlike Euler angles, the description has no
coordinate singularity (no gimbal lock), at the price of one redundant component.

References: Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §4.5;
Shepperd, *Quaternion from rotation matrix*, J. Guidance Control 1, 223 (1978);
Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed., §VII.5.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer


def _check_quaternion(q: jax.Array) -> jax.Array:
    q = jnp.asarray(q)
    if q.shape[-1:] != (4,):
        raise ValueError(f"a quaternion has shape (..., 4), got {q.shape}")
    return q


def check_nonzero_quaternion(q: jax.Array, what: str = "the quaternion") -> jax.Array:
    r"""`q`, after checking that it can stand for a rotation: finite and not zero.

    A zero quaternion is no rotation at all, and it stays zero under
    $\dot q = \tfrac12 q \otimes (0, \boldsymbol\omega)$ (a silent q = 0 run).
    A concrete value is checked at once (`ValueError`); a traced one at run time
    (`eqx.error_if`). Any other length is accepted: the rotation of $q/|q|$ is meant.
    """
    q = _check_quaternion(q)
    remedy = "use a unit quaternion, e.g. (1, 0, 0, 0) for the identity"
    if isinstance(q, Tracer):
        norm = jnp.sum(q * q, axis=-1)
        bad = ~(jnp.isfinite(norm) & (norm > 0))
        return eqx.error_if(q, jnp.any(bad), f"{what} is zero or not finite: {remedy}")
    values = np.asarray(q)
    norms = np.sum(values * values, axis=-1)
    if not np.all(np.isfinite(norms)):
        raise ValueError(f"{what} is not finite ({values}): {remedy}")
    if np.any(norms == 0):
        raise ValueError(f"{what} is zero, which is no rotation: {remedy}")
    return q


def skew(v: jax.Array) -> jax.Array:
    r"""The cross-product matrix $\hat{\mathbf v}$ with $\hat{\mathbf v}\mathbf u =
    \mathbf v \times \mathbf u$."""
    x, y, z = v[0], v[1], v[2]
    zero = jnp.zeros_like(x)
    return jnp.stack(
        [jnp.stack([zero, -z, y]), jnp.stack([z, zero, -x]), jnp.stack([-y, x, zero])]
    )


def quaternion_multiply(a: jax.Array, b: jax.Array) -> jax.Array:
    r"""Hamilton product $a \otimes b$: the rotation $b$ followed by $a$."""
    a, b = _check_quaternion(a), _check_quaternion(b)
    aw, av = a[..., 0], a[..., 1:]
    bw, bv = b[..., 0], b[..., 1:]
    w = aw * bw - jnp.sum(av * bv, axis=-1)
    v = aw[..., None] * bv + bw[..., None] * av + jnp.cross(av, bv)
    return jnp.concatenate([w[..., None], v], axis=-1)


def quaternion_conjugate(q: jax.Array) -> jax.Array:
    """$(w, -x, -y, -z)$: the inverse rotation of a unit quaternion."""
    q = _check_quaternion(q)
    return q * jnp.array([1.0, -1.0, -1.0, -1.0], dtype=q.dtype)


def axis_angle_quaternion(axis: jax.Array, angle: jax.Array) -> jax.Array:
    """The unit quaternion of a turn by `angle` about the unit vector `axis`."""
    half = 0.5 * jnp.asarray(angle)
    return jnp.concatenate(
        [jnp.cos(half)[..., None], jnp.sin(half)[..., None] * jnp.asarray(axis)],
        axis=-1,
    )


def rotation_vector_quaternion(rotation_vector: jax.Array) -> jax.Array:
    r"""The exponential map: a turn by $|\boldsymbol\theta|$ about
    $\boldsymbol\theta/|\boldsymbol\theta|$.

    Near the identity $\cos(\theta/2)$ and $\sin(\theta/2)/\theta$ are taken from
    their Taylor series in $\theta^2$, so the map and its derivatives are finite at
    $\boldsymbol\theta = 0$ (a square root of $|\boldsymbol\theta|^2$ is not).
    """
    v = jnp.asarray(rotation_vector)
    squared = jnp.sum(v * v, axis=-1)
    small = squared < _SERIES_LIMIT
    # The double `where` keeps the unused branch finite, so its gradient is too.
    angle = jnp.sqrt(jnp.where(small, 1.0, squared))
    cos_half = jnp.where(
        small, 1 - squared / 8 + squared**2 / 384, jnp.cos(0.5 * angle)
    )
    sin_half_over_angle = jnp.where(
        small, 0.5 - squared / 48 + squared**2 / 3840, jnp.sin(0.5 * angle) / angle
    )
    return jnp.concatenate(
        [cos_half[..., None], sin_half_over_angle[..., None] * v], -1
    )


# Below this |θ|² the series' first omitted terms (~|θ|⁶/46080) are under round-off.
_SERIES_LIMIT = 1e-6


def quaternion_to_matrix(q: jax.Array) -> jax.Array:
    r"""The rotation matrix $R(q)$ (body → space).

    Divides by $|q|^2$, so a quaternion that has drifted off unit length still maps
    to an exact rotation.
    """
    q = _check_quaternion(q)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    s = 2.0 / jnp.sum(q * q, axis=-1)
    rows = [
        [1 - s * (y * y + z * z), s * (x * y - w * z), s * (x * z + w * y)],
        [s * (x * y + w * z), 1 - s * (x * x + z * z), s * (y * z - w * x)],
        [s * (x * z - w * y), s * (y * z + w * x), 1 - s * (x * x + y * y)],
    ]
    return jnp.stack([jnp.stack(row, axis=-1) for row in rows], axis=-2)


def matrix_to_quaternion(rotation: jax.Array) -> jax.Array:
    r"""The unit quaternion with $w \ge 0$ of a rotation matrix (Shepperd's method).

    Each of the four components can be recovered from the diagonal; Shepperd's
    method takes the largest, so no small number is ever divided by. Here each
    candidate is the unnormalised $4 q_k\,q$, of length $4|q_k|$, and the longest is
    normalised.
    """
    r = jnp.asarray(rotation)
    if r.shape[-2:] != (3, 3):
        raise ValueError(f"a rotation matrix has shape (..., 3, 3), got {r.shape}")
    r00, r11, r22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    antisym = (r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0])
    antisym = (*antisym, r[..., 1, 0] - r[..., 0, 1])
    sym = (r[..., 0, 1] + r[..., 1, 0], r[..., 0, 2] + r[..., 2, 0])
    sym = (*sym, r[..., 1, 2] + r[..., 2, 1])
    candidates = jnp.stack(
        [
            jnp.stack([1 + r00 + r11 + r22, *antisym], -1),
            jnp.stack([antisym[0], 1 + r00 - r11 - r22, sym[0], sym[1]], -1),
            jnp.stack([antisym[1], sym[0], 1 - r00 + r11 - r22, sym[2]], -1),
            jnp.stack([antisym[2], sym[1], sym[2], 1 - r00 - r11 + r22], -1),
        ],
        axis=-2,
    )
    diagonal = jnp.stack([r00 + r11 + r22, r00, r11, r22], axis=-1)
    best = jnp.argmax(diagonal, axis=-1)
    chosen = jnp.take_along_axis(candidates, best[..., None, None], axis=-2)[..., 0, :]
    q = chosen / jnp.linalg.norm(chosen, axis=-1, keepdims=True)
    return q * jnp.where(q[..., :1] < 0, -1.0, 1.0)


def rotate(q: jax.Array, vector: jax.Array) -> jax.Array:
    """$R(q)\\,\\mathbf v$: body components to space components."""
    return jnp.einsum("...ij,...j->...i", quaternion_to_matrix(q), vector)


def quaternion_rate(q: jax.Array, omega_body: jax.Array) -> jax.Array:
    r"""$\dot q = \tfrac12\, q \otimes (0, \boldsymbol\omega_{\text{body}})$."""
    pure = jnp.concatenate([jnp.zeros_like(omega_body[..., :1]), omega_body], -1)
    return 0.5 * quaternion_multiply(q, pure)


def body_angular_velocity(q: jax.Array, q_rate: jax.Array) -> jax.Array:
    r"""$\boldsymbol\omega_{\text{body}}$ = vector part of $2\,\bar q \otimes \dot q$
    (unit $q$)."""
    return 2 * quaternion_multiply(quaternion_conjugate(q), q_rate)[..., 1:]


def space_angular_velocity(q: jax.Array, q_rate: jax.Array) -> jax.Array:
    r"""$\boldsymbol\omega_{\text{space}}$ = vector part of $2\,\dot q \otimes \bar q$
    (unit $q$)."""
    return 2 * quaternion_multiply(q_rate, quaternion_conjugate(q))[..., 1:]
