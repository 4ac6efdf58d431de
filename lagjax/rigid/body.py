r"""`RigidBody`: Euler's equations on unit quaternions and body angular momentum.

A rigid body turning about a fixed point (or its centre of mass), with body axes
along its principal axes, has the state $y = (q, \boldsymbol\Pi)$: the unit
quaternion $q$ of the body-to-space rotation $R(q)$ and the angular momentum in
body components $\boldsymbol\Pi = \mathbf I\boldsymbol\omega$,
$\mathbf I = \mathrm{diag}(I_1, I_2, I_3)$. Its equations of motion are

$$ \dot q = \tfrac12\, q \otimes (0, \boldsymbol\omega), \qquad
   \dot{\boldsymbol\Pi} = \boldsymbol\Pi \times \boldsymbol\omega
   + \boldsymbol\tau, \qquad \boldsymbol\omega = \mathbf I^{-1}\boldsymbol\Pi, $$

the second being Euler's equations (course text eq. 4.37–4.39) with the body-frame
torque $\boldsymbol\tau$. The torque comes from an orientation-dependent potential
$V(R)$ by autodiff: turning the body by a small body-frame angle $\boldsymbol
\epsilon$, $R \to R(1 + \hat{\boldsymbol\epsilon})$, does work
$\boldsymbol\tau\cdot\boldsymbol\epsilon = -\delta V$, so

$$ \boldsymbol\tau = -\frac{\partial}{\partial\boldsymbol\epsilon}
   V\big(R\,(1 + \hat{\boldsymbol\epsilon})\big)\Big|_{\boldsymbol\epsilon = 0}. $$

The energy $H = \tfrac12\boldsymbol\Pi^T\mathbf I^{-1}\boldsymbol\Pi + V(R)$ and,
without torque, the space angular momentum $\mathbf L = R\boldsymbol\Pi$ are
conserved; $|\boldsymbol\Pi| = |\mathbf L|$ is conserved by any torque-free motion.
This is a Lie–Poisson system, not a canonical one, which is why it has its own
structure-preserving solvers (`lagjax.solvers.lie_poisson`).

References: the course text §4.7–4.8; Goldstein, Poole & Safko, *Classical
Mechanics*, 3rd ed., §5.5–5.7; Marsden & Ratiu, *Introduction to Mechanics and
Symmetry*, 2nd ed., §15.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._core.solver_kinds import DefaultMethod
from lagjax._core.system import AbstractSystem
from lagjax._core.terms import RigidBodyTerm
from lagjax.mechanics.functions import as_system_function
from lagjax.mechanics.signature import call_with_arity, check_scalar, positional_arity
from lagjax.rigid.inertia import check_moments
from lagjax.rigid.quaternion import (
    check_nonzero_quaternion,
    quaternion_rate,
    quaternion_to_matrix,
    skew,
)


class RigidBody(AbstractSystem):
    r"""A rigid body in principal axes, with an optional potential $V(R)$.

    **Arguments:**
    - `moments`: the principal moments $(I_1, I_2, I_3)$ about the fixed point (or
      the centre of mass), shape `(3,)`, positive.
    - `potential`: optional `V(rotation)`, `V(rotation, t)` or
      `V(rotation, t, args)` of the body-to-space rotation matrix; it supplies the
      torque (e.g. gravity on a heavy top: `M g l * rotation[2, 2]`).

    The state is `y = (quaternion, body_momentum)`, shapes `(4,)` and `(3,)`; `t`
    defaults to 0.0 and `args` to None. Calling the body gives its energy.
    """

    moments: jax.Array
    potential: Callable | None = eqx.field(converter=as_system_function)
    potential_arity: int = eqx.field(static=True)

    def __init__(self, moments: Any, potential: Callable | None = None):
        moments = jnp.asarray(moments, dtype=float)
        if moments.shape != (3,):
            raise ValueError(
                "RigidBody needs the three principal moments (shape (3,)), got shape "
                f"{moments.shape}; diagonalise a full tensor with principal_axes"
            )
        # Concrete moments are checked now; traced (vmapped, jitted) ones at run time.
        self.moments = check_moments(moments, "RigidBody's principal moments")
        self.potential = potential
        self.potential_arity = (
            0
            if potential is None
            else positional_arity(
                potential, minimum=1, maximum=3, what="the potential V"
            )
        )

    def angular_velocity(self, body_momentum: jax.Array) -> jax.Array:
        r"""$\boldsymbol\omega = \mathbf I^{-1}\boldsymbol\Pi$ in body components."""
        return body_momentum / self.moments

    def kinetic_energy(self, body_momentum: jax.Array) -> jax.Array:
        r"""$T = \tfrac12 \sum_i \Pi_i^2 / I_i$."""
        return 0.5 * jnp.sum(body_momentum**2 / self.moments)

    def potential_energy(
        self, quaternion: jax.Array, t: Any = 0.0, args: Any = None
    ) -> jax.Array:
        """V(R(q), t, args); zero for a free body."""
        if self.potential is None:
            return jnp.zeros((), dtype=self.moments.dtype)
        rotation = quaternion_to_matrix(quaternion)
        return self._potential_of_matrix(rotation, t, args)

    def _potential_of_matrix(self, rotation, t, args) -> jax.Array:
        assert self.potential is not None
        value = call_with_arity(self.potential, self.potential_arity, rotation, t, args)
        return check_scalar(value, "the potential V")

    def __call__(
        self,
        quaternion: jax.Array,
        body_momentum: jax.Array,
        t: Any = 0.0,
        args: Any = None,
    ) -> jax.Array:
        """The energy T + V."""
        return self.kinetic_energy(body_momentum) + self.potential_energy(
            quaternion, t, args
        )

    def energy(
        self,
        quaternion: jax.Array,
        body_momentum: jax.Array,
        t: Any = 0.0,
        args: Any = None,
    ) -> jax.Array:
        """The energy T + V (the same as calling the body)."""
        return self(quaternion, body_momentum, t, args)

    def torque(
        self, quaternion: jax.Array, t: Any = 0.0, args: Any = None
    ) -> jax.Array:
        r"""Body-frame torque $-\partial V(R(1 + \hat\epsilon))/\partial\epsilon$ at 0."""
        if self.potential is None:
            return jnp.zeros(3, dtype=self.moments.dtype)
        rotation = quaternion_to_matrix(quaternion)

        def turned(angle):
            return self._potential_of_matrix(
                rotation @ (jnp.eye(3, dtype=rotation.dtype) + skew(angle)), t, args
            )

        return -jax.grad(turned)(jnp.zeros(3, dtype=rotation.dtype))

    def velocity(
        self,
        quaternion: jax.Array,
        body_momentum: jax.Array,
        t: Any = 0.0,
        args: Any = None,
    ) -> jax.Array:
        r"""$\dot q = \tfrac12 q \otimes (0, \boldsymbol\omega)$."""
        return quaternion_rate(quaternion, self.angular_velocity(body_momentum))

    def vector_field(
        self,
        quaternion: jax.Array,
        body_momentum: jax.Array,
        t: Any = 0.0,
        args: Any = None,
    ) -> tuple[jax.Array, jax.Array]:
        r"""$(\dot q, \dot{\boldsymbol\Pi})$: the orientation rate and Euler's
        equations."""
        omega = self.angular_velocity(body_momentum)
        momentum_rate = jnp.cross(body_momentum, omega)
        if self.potential is not None:
            momentum_rate = momentum_rate + self.torque(quaternion, t, args)
        return quaternion_rate(quaternion, omega), momentum_rate

    def angular_momentum_space(
        self, quaternion: jax.Array, body_momentum: jax.Array
    ) -> jax.Array:
        r"""$\mathbf L = R(q)\,\boldsymbol\Pi$, conserved without torque."""
        return quaternion_to_matrix(quaternion) @ body_momentum

    def angular_velocity_space(
        self, quaternion: jax.Array, body_momentum: jax.Array
    ) -> jax.Array:
        r"""$\boldsymbol\omega$ in space components, $R(q)\,\mathbf I^{-1}\boldsymbol\Pi$."""
        return quaternion_to_matrix(quaternion) @ self.angular_velocity(body_momentum)

    def state_from_angular_velocity(
        self, quaternion: jax.Array, omega_body: jax.Array
    ) -> tuple[jax.Array, jax.Array]:
        r"""The state $(q, \mathbf I\boldsymbol\omega)$ from an orientation and a body
        angular velocity; `q` is normalised."""
        quaternion = jnp.asarray(quaternion, dtype=self.moments.dtype)
        quaternion = check_nonzero_quaternion(quaternion, "the orientation")
        return quaternion / jnp.linalg.norm(quaternion), self.moments * omega_body

    # -- AbstractSystem: the state is (quaternion, body momentum) ------------------
    # Imports are local: the solvers and terms are built on this module.

    @property
    def second_is_momentum(self) -> bool:
        return True

    def default_method(self, dt: Any) -> DefaultMethod:
        """`RigidBodyYoshida4` (Lie–Poisson splitting) with `dt`, else adaptive
        `Tsit5` with the quaternion projected back to unit length."""
        if dt is None:
            return DefaultMethod.ADAPTIVE_UNIT_QUATERNION
        return DefaultMethod.LIE_POISSON

    def integration(self, solver: Any, y0: Any, t0: Any, args: Any) -> Any:
        """The `RigidBodyTerm`: any solver integrates it, Lie–Poisson ones read the
        body from it."""
        return RigidBodyTerm(self), y0, self

    def state_velocity(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return self.velocity(q, second, t, args)

    def state_rate(self, q: Any, second: Any, t: Any, args: Any) -> tuple[Any, Any]:
        return self.vector_field(q, second, t, args)

    def checked_state_pair(self, first: Any, second: Any) -> tuple[Any, Any]:
        """(quaternion of shape (4,), nonzero; body momentum of shape (3,))."""
        if jnp.shape(first) != (4,) or jnp.shape(second) != (3,):
            raise ValueError(
                "a RigidBody's y0 is (quaternion of shape (4,), body angular momentum "
                f"of shape (3,)), got shapes {jnp.shape(first)} and "
                f"{jnp.shape(second)}; RigidBody.state_from_angular_velocity builds one"
            )
        return check_nonzero_quaternion(first, "y0's quaternion"), second

    def accepted_terms(self) -> tuple[type, ...]:
        return (RigidBodyTerm,)

    def phase_space_obstacle(self) -> str | None:
        return (
            f"Phase-space tools take a Lagrangian, a Hamiltonian or a scene of one; got "
            f"{type(self).__name__}. A rigid body's quaternion state has a "
            "redundant direction: write its Lagrangian in Euler angles instead."
        )

    def state_momentum(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return second

    def state_energy(self, q: Any, second: Any, t: Any, args: Any) -> jax.Array:
        return self(q, second, t, args)
