r"""Linearization about an equilibrium: the state-space matrices $A$, $B$ and stability.

Near an equilibrium $x_0$ (with input $u = 0$) the equations of motion
$\dot x = f(x, u)$ become $\dot{\delta x} = A\,\delta x + B\,u$ with
$A = \partial f/\partial x$ and $B = \partial f/\partial u$ — what SymPy
mechanics' `linearize` gives, here by forward-mode autodiff of lagjax's own
vector fields. The input $u$ is a generalized force $Q = S u$ with a given input
matrix $S$ (n × m): its value at the operating point is all a linearization needs.

| system | state $x$ | $B$ |
|---|---|---|
| `Lagrangian` | $(q, \dot q)$ | $(0;\ M^{-1}S)$ |
| `Hamiltonian`, `SeparableHamiltonian` | $(q, p)$ | $(0;\ S)$ |
| `Lagrangian` with constraints | chart $(s, w)$ on the manifold (below) | projected |
| `RigidBody` | $(\boldsymbol\epsilon, \delta\boldsymbol\Pi)$ (below) | $(0;\ S)$, S a body torque |

**Constraints.** The states allowed by holonomic $g(q) = 0$ and velocity
constraints $c(q, \dot q) = 0$ (including $\dot g = 0$) form an invariant manifold
of the index-reduced equations; its tangent space at $x_0$ is invariant under $A$.
With $N_q$ spanning $\ker G$ ($G = \partial g/\partial q$) and $N_v$ spanning
$\ker \partial c/\partial\dot q$, the tangent vectors are
$P\,(s, w)$, $P = \begin{pmatrix}N_q & 0\\ -C_v^+C_qN_q & N_v\end{pmatrix}$
($C_q$, $C_v$ the derivatives of the velocity rows), and the reduced matrices are
$P^+AP$ and $P^+B$. The constraint forces' dependence on $q$ — the curvature of the
manifold, which makes a Cartesian pendulum's frequency $\sqrt{g/l}$ — comes in
through the derivative of the index-reduced acceleration. The drift directions of
the unreduced system (double zero eigenvalues, $g = a + bt$) are left out.

**Rigid body at a relative equilibrium.** A steady rotation $\boldsymbol\Pi_0$ with
$\boldsymbol\Pi_0\times\boldsymbol\omega_0 + \boldsymbol\tau(R_0) = 0$,
$\boldsymbol\omega_0 = \mathbf I^{-1}\boldsymbol\Pi_0$, turns the orientation as
$R_0(t) = R_0e^{t\hat\omega_0}$. The chart $R = R_0(t)\,e^{\hat\epsilon}$,
$\boldsymbol\Pi = \boldsymbol\Pi_0 + \delta\boldsymbol\Pi$ is minimal (six
coordinates for the six-dimensional state) and co-rotating, so the motion near the
steady rotation is an equilibrium of

$$ \dot{\boldsymbol\epsilon} \approx \mathbf I^{-1}\boldsymbol\Pi
   - e^{-\hat\epsilon}\boldsymbol\omega_0, \qquad
   \dot{\boldsymbol\Pi} = \boldsymbol\Pi\times\mathbf I^{-1}\boldsymbol\Pi
   + \boldsymbol\tau(R_0e^{\hat\epsilon}), $$

exact to first order (the kinematic factor $d\exp^{-1}_\epsilon$ multiplies a term
that vanishes at the equilibrium). This assumes the potential is symmetric about
the spin's space axis, $V(e^{t\hat\Omega}R) = V(R)$ (gravity on a top spinning
about the vertical), so that the steady rotation exists at all times; a free body
qualifies about any principal axis. Its eigenvalues show the intermediate-axis
instability and the sleeping top's threshold $\omega_3^2 > 4MglI_1/I_3^2$.

References: SymPy `sympy.physics.mechanics.linearize` (Peterson, Gede & Hubbard,
Multibody Syst. Dyn. 31, 2014); Meirovitch, *Methods of Analytical Dynamics*
§6.4–6.6; Marsden & Ratiu, *Introduction to Mechanics and Symmetry* §15.10
(stability of rigid-body rotations); Goldstein §5.7 (the sleeping top).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._core.system import AbstractSystem
from lagjax.mechanics import stability
from lagjax.mechanics.constrained_modes import null_space
from lagjax.mechanics.constraints import least_correction
from lagjax.mechanics.hamiltonian import AbstractHamiltonian
from lagjax.mechanics.lagrangian import Lagrangian
from lagjax.rigid.body import RigidBody
from lagjax.rigid.quaternion import (
    quaternion_multiply,
    quaternion_to_matrix,
    rotation_vector_quaternion,
)


class LinearizedSystem(eqx.Module):
    r"""What `linearize` returns; it unpacks as `A, B = ...` (B is None without inputs).

    - `A` (d, d), `B` (d, m) or None: $\dot{\delta x} = A\,\delta x + B\,u$.
    - `eigenvalues` (d,), complex, and `stability` (d,), int (0 stable, 1 marginal,
      2 unstable; see `lagjax.mechanics.stability`); `verdict()` and `labels()` in
      words.
    - `operating_point` (D,): the flat state linearized about (for a rigid body
      the quaternion and the body momentum, 7 numbers).
    - `basis` (D, d) or None: the chart's directions in the flat state (constrained
      systems; for a rigid body the chart is (ε, δΠ), see the module docstring).
    """

    A: jax.Array
    B: jax.Array | None
    eigenvalues: jax.Array
    stability: jax.Array
    operating_point: jax.Array
    basis: jax.Array | None

    def __iter__(self) -> Iterator[jax.Array | None]:
        return iter((self.A, self.B))

    @property
    def growth_rate(self) -> jax.Array:
        """The largest Re λ: the fastest e-folding rate (≤ 0 when nothing grows)."""
        return jnp.max(jnp.real(self.eigenvalues))

    def labels(self) -> tuple[str, ...]:
        """'stable', 'marginal' or 'unstable' per eigenvalue (concrete values only)."""
        return stability.labels(self.stability)

    def verdict(self) -> str:
        """'unstable' if any eigenvalue has Re λ > 0, else 'marginal' if one is zero,
        else 'stable' — linear (spectral) stability only."""
        return stability.verdict(self.stability)


def _input_matrix(inputs: Any, n: int, dtype) -> jax.Array | None:
    if inputs is None:
        return None
    matrix = jnp.asarray(inputs, dtype=dtype)
    if matrix.ndim == 1:
        matrix = matrix[:, None]
    if matrix.ndim != 2 or matrix.shape[0] != n:
        raise ValueError(
            f"inputs must be the input matrix S of the generalized force Q = S u, "
            f"shape ({n}, m) for {n} coordinates; got shape {matrix.shape}"
        )
    return matrix


def _flat_pair(state: Any, names: tuple[str, str]) -> tuple[jax.Array, Callable, int]:
    if not (isinstance(state, (tuple, list)) and len(state) == 2):
        raise ValueError(
            f"the equilibrium must be the state ({names[0]}, {names[1]}) as a pair, "
            f"like simulate's y0; got {type(state).__name__}"
        )
    first, unravel = ravel_pytree(state[0])
    second, _ = ravel_pytree(state[1])
    if first.shape != second.shape:
        raise ValueError(
            f"{names[0]} and {names[1]} must have the same structure; got "
            f"{first.shape[0]} and {second.shape[0]} numbers"
        )
    if first.shape[0] == 0:
        raise ValueError(
            f"the equilibrium's {names[0]} has no coordinates (shape "
            f"{jnp.shape(state[0])}): linearize needs at least one; pass {names[0]} "
            "with one entry per coordinate, e.g. jnp.array([0.0]) for one"
        )
    return jnp.concatenate([first, second]), unravel, first.shape[0]


class _Parts(NamedTuple):
    """A system's flat vector field, operating point, input block and chart."""

    field: Callable
    state: jax.Array
    inputs: jax.Array | None
    basis: jax.Array | None
    constraint_residual: jax.Array | None
    # The state as the user gave it, flat, when the chart's origin is not it.
    operating_point: jax.Array | None = None


def _lagrangian_parts(lag: Lagrangian, state, t, args, inputs) -> _Parts:
    x0, unravel, n = _flat_pair(state, ("q", "qdot"))

    def field(x):
        q, v = unravel(x[:n]), unravel(x[n:])
        acceleration = lag.acceleration(q, v, t, args)
        return jnp.concatenate([x[n:], ravel_pytree(acceleration)[0]])

    q0, v0 = unravel(x0[:n]), unravel(x0[n:])
    matrix = _input_matrix(inputs, n, x0.dtype)
    block = None
    if matrix is not None:
        mass = lag.mass_matrix(q0, v0, t, args)
        rates = jnp.linalg.solve(mass, matrix)
        if lag.constraints is not None:
            rates = _admissible(lag, q0, t, args, mass, rates)
        block = jnp.concatenate([jnp.zeros_like(matrix), rates])
    if lag.constraints is None:
        return _Parts(field, x0, block, None, None)
    basis, residual = _constraint_chart(lag, x0, unravel, n, t, args)
    return _Parts(field, x0, block, basis, residual)


def _admissible(lag, q0, t, args, mass, rates):
    """Add to each column of accelerations the constraint force's reply to it."""
    assert lag.constraints is not None
    jacobian = lag.constraints.jacobian(q0, t, args)

    def correct(column):
        delta, _, _ = least_correction(mass, jacobian, -jacobian @ column)
        return column + delta

    return jax.vmap(correct, in_axes=1, out_axes=1)(rates)


def _constraint_chart(lag, x0, unravel, n, t, args):
    """Tangent basis P of the constraint manifold at x0, and the residual there."""
    constraints = lag.constraints
    assert constraints is not None
    q0, v0 = unravel(x0[:n]), unravel(x0[n:])

    def position(q_flat):
        return constraints.position_residual(unravel(q_flat), t, args)

    def velocity(q_flat, v_flat):
        return constraints.velocity_residual(unravel(q_flat), unravel(v_flat), t, args)

    n_q = null_space(jax.jacfwd(position)(x0[:n]), "∂g/∂q")
    c_q, c_v = jax.jacfwd(velocity, argnums=(0, 1))(x0[:n], x0[n:])
    n_v = null_space(c_v, "∂c/∂q̇")
    lift = -jnp.linalg.pinv(c_v) @ c_q @ n_q
    basis = jnp.block(
        [
            [n_q, jnp.zeros((n, n_v.shape[1]), x0.dtype)],
            [lift, n_v],
        ]
    )
    residual = jnp.concatenate(
        [
            constraints.position_residual(q0, t, args),
            constraints.velocity_residual(q0, v0, t, args),
        ]
    )
    return basis, residual


def _hamiltonian_parts(ham: AbstractHamiltonian, state, t, args, inputs) -> _Parts:
    x0, unravel, n = _flat_pair(state, ("q", "p"))

    def field(x):
        rates = ham.vector_field(unravel(x[:n]), unravel(x[n:]), t, args)
        return jnp.concatenate([ravel_pytree(r)[0] for r in rates])

    matrix = _input_matrix(inputs, n, x0.dtype)
    block = (
        None if matrix is None else jnp.concatenate([jnp.zeros_like(matrix), matrix])
    )
    return _Parts(field, x0, block, None, None)


def _rigid_body_parts(body, state, t, args, inputs) -> _Parts:
    if not (isinstance(state, (tuple, list)) and len(state) == 2):
        raise ValueError(
            "for a rigid body the equilibrium is the state (quaternion, "
            f"body_momentum), like simulate's y0; got {type(state).__name__}"
        )
    quaternion = jnp.asarray(state[0], dtype=body.moments.dtype)
    momentum0 = jnp.asarray(state[1], dtype=body.moments.dtype)
    if quaternion.shape != (4,) or momentum0.shape != (3,):
        raise ValueError(
            "for a rigid body the equilibrium is (quaternion (4,), body_momentum "
            f"(3,)); got shapes {quaternion.shape} and {momentum0.shape}"
        )
    quaternion = quaternion / jnp.linalg.norm(quaternion)
    omega0 = body.angular_velocity(momentum0)

    def field(x):
        turn = rotation_vector_quaternion(x[:3])
        momentum = momentum0 + x[3:]
        frame_rate = quaternion_to_matrix(turn).T @ omega0
        _, momentum_rate = body.vector_field(
            quaternion_multiply(quaternion, turn), momentum, t, args
        )
        return jnp.concatenate(
            [body.angular_velocity(momentum) - frame_rate, momentum_rate]
        )

    x0 = jnp.zeros(6, dtype=body.moments.dtype)  # the chart's origin
    matrix = _input_matrix(inputs, 3, x0.dtype)
    block = (
        None if matrix is None else jnp.concatenate([jnp.zeros_like(matrix), matrix])
    )
    point = jnp.concatenate([quaternion, momentum0])
    return _Parts(field, x0, block, None, None, point)


def _parts(system, state, t, args, inputs) -> _Parts:
    if isinstance(system, Lagrangian):
        return _lagrangian_parts(system, state, t, args, inputs)
    if isinstance(system, AbstractHamiltonian):
        return _hamiltonian_parts(system, state, t, args, inputs)
    if isinstance(system, RigidBody):
        return _rigid_body_parts(system, state, t, args, inputs)
    raise TypeError(
        "linearize needs a lagjax Lagrangian, Hamiltonian, SeparableHamiltonian, "
        f"RigidBody or scene; got {type(system).__name__}"
    )


def linearize(
    system: Any,
    equilibrium: Any,
    args: Any = None,
    inputs: Any = None,
    *,
    t: Any = 0.0,
    check_equilibrium: bool = True,
    equilibrium_tol: float = stability.EQUILIBRIUM_TOL,
) -> LinearizedSystem:
    r"""The linearization $\dot{\delta x} = A\,\delta x + B\,u$ about an equilibrium.

    **Arguments:**
    - `system`: a `Lagrangian` (constrained or not), `Hamiltonian`,
      `SeparableHamiltonian`, `RigidBody` or a scene (whose `args` default to it).
    - `equilibrium`: the state, as simulate's `y0`: `(q, qdot)` for a Lagrangian,
      `(q, p)` for a Hamiltonian, `(quaternion, body_momentum)` for a rigid body
      (a steady rotation: a relative equilibrium).
    - `inputs`: None, or the input matrix S (n × m; a 1-D array is one input) of a
      generalized force $Q = Su$ (a body-frame torque for a rigid body).
    - `check_equilibrium`: refuse (default) a state where the vector field does not
      vanish (for a constrained system, also one off the constraint manifold);
      pass False to linearize about any operating point, e.g. a steady motion in a
      cyclic coordinate. `equilibrium_tol`: see `lagjax.mechanics.stability`.

    **Returns:** a `LinearizedSystem` (unpacks as `A, B`), with the eigenvalues of
    A and a stability verdict. See the module docstring for each system's state.
    """
    if isinstance(system, AbstractSystem):
        system, args = system.resolve(args)  # a scene: its system and itself
    jacobian, rate, parts = _derivatives(system, equilibrium, t, args, inputs)
    jacobian = _require_finite(jacobian, rate)
    if check_equilibrium:
        jacobian = stability.check_stationary(
            jacobian,
            rate,
            jnp.linalg.norm(jacobian),
            parts.state,
            tol=equilibrium_tol,
            what="state's rate of change (the residual of the equations of motion)",
            remedy="Find one first (lj.relative_equilibrium), or pass "
            "check_equilibrium=False to linearize about this operating point anyway.",
        )
        if parts.constraint_residual is not None:
            jacobian = stability.check_stationary(
                jacobian,
                parts.constraint_residual,
                jnp.asarray(1.0),
                parts.state,
                tol=equilibrium_tol,
                what="constraint residual (g, ġ, c) (the state is off the manifold)",
                remedy="Start from a state that satisfies the constraints.",
            )
    point = parts.state if parts.operating_point is None else parts.operating_point
    return _reduce(jacobian, parts.inputs, point, parts.basis)


def _no_field(x):
    raise AssertionError("the field is only used inside _derivatives")


_NOT_FINITE = (
    "The linearization is not finite at this state: is the mass matrix ∂²L/∂q̇∂q̇ "
    "(or ∂²H/∂p∂p) singular there, or a coordinate singular (e.g. Euler angles at "
    "gimbal lock)? Linearize in other coordinates or at another state."
)


def _require_finite(jacobian: jax.Array, rate: jax.Array) -> jax.Array:
    bad = ~(jnp.all(jnp.isfinite(jacobian)) & jnp.all(jnp.isfinite(rate)))
    if stability.is_concrete(bad):
        if bool(bad):
            raise ValueError(_NOT_FINITE)
        return jacobian
    return eqx.error_if(jacobian, bad, _NOT_FINITE)


# Compiled as a whole: op-by-op dispatch of the nested derivatives costs seconds.
@eqx.filter_jit
def _derivatives(system, equilibrium, t, args, inputs):
    """(∂f/∂x, f) at the operating point, and the system's parts (arrays only)."""
    parts = _parts(system, equilibrium, t, args, inputs)
    jacobian = jax.jacfwd(parts.field)(parts.state)
    arrays = parts._replace(field=_no_field)  # a function cannot leave a jit
    return jacobian, parts.field(parts.state), arrays


@jax.jit
def _reduce(a, b, state, basis) -> LinearizedSystem:
    """Onto the chart (constrained systems), then eigenvalues and their stability."""
    if basis is not None:
        left = jnp.linalg.pinv(basis)
        a = left @ a @ basis
        b = None if b is None else left @ b
    eigenvalues = jnp.linalg.eigvals(a)
    codes = stability.classify(eigenvalues, conservative=False)
    return LinearizedSystem(a, b, eigenvalues, codes, state, basis)
