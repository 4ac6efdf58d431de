r"""Constraints and the forces that maintain them: Lagrange multipliers.

A system with coordinates $q \in \mathbb R^n$ and Lagrangian $L(q, \dot q, t)$ may be
restricted by

- **holonomic** constraints $g(q, t) = 0$ (k_h equations; *rheonomic* when they
  depend on t), and
- **nonholonomic** (velocity) constraints $c(q, \dot q, t) = A(q, t)\,\dot q +
  b(q, t) = 0$, linear in $\dot q$ but not the time derivative of any $g$ — rolling
  without slipping is the canonical example (the course text §3.1.3).

A holonomic constraint enters the engine through its time derivative
$\dot g = G\dot q + \partial g/\partial t$ ($G = \partial g/\partial q$), so both kinds
are one list of velocity-level constraints $c(q, \dot q, t) = 0$ with Jacobian
$A = \partial c/\partial\dot q$. Constraint forces do no work on motions allowed by
the constraints (d'Alembert), so they are $A^T\lambda$ and the Lagrange–d'Alembert
equations read

$$ M\ddot q = f + A^T\lambda, \qquad A\ddot q = -\beta, $$

with $M = \partial^2L/\partial\dot q^2$, $f$ the rest of the Euler–Lagrange
equations (so $M^{-1}f$ is the *free* acceleration $a$), and the bias
$\beta = \partial c/\partial q\,\dot q + \partial c/\partial t$ — for a holonomic
constraint $\dot q^T g_{qq}\dot q + 2g_{qt}\dot q + g_{tt}$, the second derivative of
g along the motion with $\ddot q = 0$, one nested forward-mode pass here. This is
the index reduction to the acceleration level. Writing $\ddot q = a + \delta$, the
correction solves the saddle-point system

$$ \begin{pmatrix} M & A^T \\ A & 0 \end{pmatrix}
   \begin{pmatrix} \delta \\ -\lambda \end{pmatrix} =
   \begin{pmatrix} 0 \\ -\beta - A a \end{pmatrix}, $$

i.e. δ is the smallest correction in the kinetic metric that makes the acceleration
admissible (Gauss's principle of least constraint). The matrix is regular exactly
when A has full row rank and M is positive definite on its null space; otherwise
the constraints are redundant or degenerate at that state and the multipliers are
not defined — an error, not a guess.

Integrating the reduced equations lets $g$ and $c$ drift with the truncation
error. Two remedies: Baumgarte stabilization (`baumgarte_rate` α replaces
$\ddot g = 0$ by $\ddot g + 2\alpha\dot g + \alpha^2 g = 0$ and $\dot c = 0$ by
$\dot c + \alpha c = 0$, which damps the drift but does not remove it), and
projection back onto the constraint manifold after every step, which keeps it at
round-off (`lagjax.solvers.projection`; `simulate` does this for every constrained
Lagrangian).

References: the course text §3.1 (holonomic, nonholonomic, rheonomic constraints,
rolling without slipping); Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed.,
§2.4 (Lagrange multipliers); Hairer, Lubich & Wanner, *Geometric Numerical
Integration*, 2nd ed., §VII.1 (index reduction); Bloch, *Nonholonomic Mechanics and
Control*, §1.3–1.4 (Lagrange–d'Alembert equations); Baumgarte, Comput. Methods Appl.
Mech. Eng. 1, 1 (1972).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.core import Tracer
from jax.flatten_util import ravel_pytree

from lagjax._core.system_protocols import LagrangianLike
from lagjax._linalg.small_solves import solve_dense_in_step
from lagjax.mechanics.functions import as_system_function
from lagjax.mechanics.signature import call_with_arity, positional_arity

_RANK_MESSAGE = (
    "The constraint Jacobian ∂c/∂q̇ is rank-deficient at this state (or the mass "
    "matrix is singular on the motions the constraints allow), so the constraint "
    "forces are not determined. Are two constraints redundant, or is a constraint "
    "degenerate here (e.g. g = |x|² − l² at x = 0)?"
)


def _constraint_vector(value: Any, what: str) -> jax.Array:
    """Trace-time check of a constraint function's output; returns it as (k,)."""
    value = jnp.asarray(value)
    if value.ndim > 1:
        raise ValueError(
            f"{what} must return a scalar or a 1-D array (one entry per constraint), "
            f"but returned an array of shape {value.shape}"
        )
    if not jnp.issubdtype(value.dtype, jnp.floating):
        raise ValueError(f"{what} must return real floats, but returned {value.dtype}")
    return jnp.reshape(value, (-1,))


class Constraints(eqx.Module):
    r"""Holonomic and nonholonomic constraints on a Lagrangian system.

    **Arguments:**
    - `holonomic`: `g(q)`, `g(q, t)` or `g(q, t, args)` returning a scalar or a 1-D
      array; the motion keeps $g(q, t) = 0$.
    - `velocity`: `c(q, qdot)`, `c(q, qdot, t)` or `c(q, qdot, t, args)`, linear in
      `qdot`, returning a scalar or 1-D array; the motion keeps $c = 0$.
    - `baumgarte_rate`: α ≥ 0 (1/s) of Baumgarte's stabilization; 0 (the default)
      enforces the constraints at the acceleration level only.

    Use it as `Lagrangian(L, constraints=Constraints(...))`; `Lagrangian(L,
    constraints=g)` is short for `Constraints(holonomic=g)`. Multipliers are ordered
    holonomic rows first, then velocity rows.
    """

    holonomic: Callable | None = eqx.field(converter=as_system_function)
    holonomic_arity: int = eqx.field(static=True)
    velocity: Callable | None = eqx.field(converter=as_system_function)
    velocity_arity: int = eqx.field(static=True)
    baumgarte_rate: float = eqx.field(static=True)

    def __init__(
        self,
        holonomic: Callable | None = None,
        *,
        velocity: Callable | None = None,
        baumgarte_rate: float = 0.0,
    ):
        if holonomic is None and velocity is None:
            raise ValueError("Constraints needs a holonomic or a velocity constraint")
        self.holonomic = holonomic
        self.holonomic_arity = (
            0
            if holonomic is None
            else positional_arity(
                holonomic, minimum=1, maximum=3, what="the holonomic constraint g"
            )
        )
        self.velocity = velocity
        self.velocity_arity = (
            0
            if velocity is None
            else positional_arity(
                velocity, minimum=2, maximum=4, what="the velocity constraint c"
            )
        )
        if not baumgarte_rate >= 0:
            raise ValueError(f"baumgarte_rate must be ≥ 0, got {baumgarte_rate}")
        self.baumgarte_rate = float(baumgarte_rate)

    def position_residual(self, q: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        """g(q, t) as a (k_h,) array; empty without holonomic constraints."""
        if self.holonomic is None:
            return jnp.zeros((0,), dtype=ravel_pytree(q)[0].dtype)
        value = call_with_arity(self.holonomic, self.holonomic_arity, q, t, args)
        return _constraint_vector(value, "the holonomic constraint g")

    def velocity_residual(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None
    ) -> jax.Array:
        """The velocity-level residual (ġ, c) as a (k,) array."""
        rows = []
        if self.holonomic is not None:
            t = jnp.asarray(t, dtype=ravel_pytree(q)[0].dtype)
            _, g_dot = jax.jvp(
                lambda qq, tt: self.position_residual(qq, tt, args),
                (q, t),
                (qdot, jnp.ones_like(t)),
            )
            rows.append(g_dot)
        if self.velocity is not None:
            value = call_with_arity(
                self.velocity, self.velocity_arity, q, qdot, t, args
            )
            rows.append(_constraint_vector(value, "the velocity constraint c"))
        return jnp.concatenate(rows)

    def jacobian(self, q: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        """A = ∂c/∂q̇, shape (k, n) in the raveled coordinates (G for holonomic rows)."""
        q_flat, unravel = ravel_pytree(q)
        return jax.jacfwd(lambda v: self.velocity_residual(q, unravel(v), t, args))(
            jnp.zeros_like(q_flat)
        )

    def acceleration_target(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None
    ) -> jax.Array:
        r"""The right-hand side of $A\ddot q = \ldots$: $-\beta$ minus stabilization."""
        t = jnp.asarray(t, dtype=ravel_pytree(q)[0].dtype)
        residual, bias = jax.jvp(
            lambda qq, tt: self.velocity_residual(qq, qdot, tt, args),
            (q, t),
            (qdot, jnp.ones_like(t)),
        )
        target = -bias
        rate = self.baumgarte_rate
        if rate > 0:
            # g̈ + 2α ġ + α² g = 0 on holonomic rows, ċ + α c = 0 on velocity rows.
            holonomic = self.position_residual(q, t, args)
            k_h = holonomic.shape[0]
            damping = jnp.concatenate(
                [2 * rate * residual[:k_h] + rate**2 * holonomic, rate * residual[k_h:]]
            )
            target = target - damping
        return target


def least_correction(
    mass: jax.Array, jacobian: jax.Array, target: jax.Array
) -> tuple[jax.Array, jax.Array, jax.Array]:
    r"""The smallest δ in the metric M with $A\delta$ = `target`, and its multipliers.

    Solves $\begin{pmatrix} M & A^T \\ A & 0\end{pmatrix}
    \begin{pmatrix}\delta \\ -\lambda\end{pmatrix} =
    \begin{pmatrix} 0 \\ \text{target}\end{pmatrix}$, so $M\delta = A^T\lambda$.
    Returns `(delta, multipliers, singular)`.
    """
    n, k = mass.shape[0], jacobian.shape[0]
    saddle = jnp.block([[mass, jacobian.T], [jacobian, jnp.zeros((k, k), mass.dtype)]])
    rhs = jnp.concatenate([jnp.zeros(n, mass.dtype), target])
    solution, singular = solve_dense_in_step(saddle, rhs)
    return solution[:n], -solution[n:], singular


def check_constraint_count(constraints: Constraints, q: Any, t: Any, args: Any):
    """Trace-time check: no more independent constraints than coordinates."""
    n = ravel_pytree(q)[0].shape[0]
    k = jax.eval_shape(constraints.velocity_residual, q, q, t, args).shape[0]
    if k > n:
        raise ValueError(
            f"{k} constraints on {n} coordinates: at most {n} can be independent"
        )


# Compiled so that eager calls do not dispatch op by op; inlined under an outer jit.
@eqx.filter_jit
def constrained_motion(
    lagrangian: LagrangianLike,
    q: Any,
    qdot: Any,
    t: Any,
    args: Any,
    free_acceleration: Any,
    *,
    check: bool | str,
) -> tuple[Any, jax.Array, Any]:
    """(q̈, λ, Aᵀλ) from the unconstrained (free) acceleration of `lagrangian`.

    `check` is the verdict on a singular saddle-point matrix (rank-deficient
    constraint Jacobian), as for the mass matrix in `Lagrangian.acceleration`:
    True raises a run-time error (`eqx.error_if`, a branch per call), `"nan"`
    makes q̈, λ and Aᵀλ NaN (one select, which stays in a fused step), False
    leaves inf/NaN or noise, which `simulate`'s projection step reports.
    """
    constraints = lagrangian.constraints
    assert constraints is not None
    check_constraint_count(constraints, q, t, args)
    free_flat, unravel = ravel_pytree(free_acceleration)
    jacobian = constraints.jacobian(q, t, args)
    target = constraints.acceleration_target(q, qdot, t, args) - jacobian @ free_flat
    mass = lagrangian.mass_matrix(q, qdot, t, args)
    correction, multipliers, singular = least_correction(mass, jacobian, target)
    correction, multipliers = apply_rank_check(
        (correction, multipliers), singular, check
    )
    force = unravel(jacobian.T @ multipliers)
    return unravel(free_flat + correction), multipliers, force


def apply_rank_check(x: Any, singular: jax.Array, check: bool | str) -> Any:
    """`check`'s verdict on a singular saddle-point matrix: every leaf of `x` NaN
    ("nan"), a run-time error (True), or nothing (False)."""
    if check == "nan":
        return jax.tree_util.tree_map(lambda a: jnp.where(singular, jnp.nan, a), x)
    if check:
        return raise_if_rank_deficient(x, singular)
    return x


def raise_if_rank_deficient(x: Any, singular: jax.Array) -> Any:
    """Attach the rank-deficient-constraints run-time error to `x` (works in jit)."""
    return eqx.error_if(x, singular, _RANK_MESSAGE)


# A start counts as on the constraints when its residuals are round-off of the
# coordinates' and velocities' own size (the projection itself reaches ~1e-15).
_START_TOLERANCE = 1e-9


@eqx.filter_jit
def _start_residuals(constraints: Constraints, q: Any, qdot: Any, t: Any, args: Any):
    """(state scales, largest position and velocity residuals) at the start.

    One compiled call: evaluated eagerly, the residuals of a constrained scene
    dispatched (and compiled) 27–47 small programs before every run.
    """
    scale_q = 1.0 + jnp.max(jnp.abs(ravel_pytree(q)[0]))
    scale_v = 1.0 + jnp.max(jnp.abs(ravel_pytree(qdot)[0]))
    position = jnp.max(jnp.abs(constraints.position_residual(q, t, args)), initial=0.0)
    velocity = jnp.max(
        jnp.abs(constraints.velocity_residual(q, qdot, t, args)), initial=0.0
    )
    return scale_q, scale_v, position, velocity


def refuse_start_off_constraints(
    constraints: Constraints, q: Any, qdot: Any, t: Any, args: Any
) -> tuple[Any, Any]:
    """`(q, q̇)` unchanged if they satisfy the constraints, else a clear error.

    Projecting a start that violates the constraints onto them without a word
    changes the motion (a `CartesianPendulum` started 1.5× too long lost a third
    of its energy that way). Checked when the values are concrete; under a trace
    the error is attached at run time (`eqx.error_if`), once, before the loop.
    """
    scale_q, scale_v, position, velocity = _start_residuals(
        constraints, q, qdot, t, args
    )
    # In float32 the start itself carries round-off of ~1e-7: the tolerance is never
    # below a hundred ulps of the state's dtype.
    eps = float(jnp.finfo(jnp.result_type(scale_q)).eps)
    tolerance = max(_START_TOLERANCE, 100 * eps)
    violated = (position > tolerance * scale_q) | (velocity > tolerance * scale_v)
    message = (
        "The initial state violates the constraints: max |g(q0, t0)| = {}, max "
        "|ġ or c(q0, q̇0, t0)| = {} (tolerance 1e-9, or 100 ulps, of the state's "
        "size). Start on "
        "the constraint manifold, e.g. (q0, q̇0), _ = lagjax.solvers.projection."
        "project_onto_constraints(lagrangian, q0, q̇0, t0, args) — the smallest "
        "change in the kinetic metric — if a projection is what you want."
    )
    if not isinstance(violated, Tracer):
        if bool(violated):
            raise ValueError(message.format(float(position), float(velocity)))
        return q, qdot
    return eqx.error_if((q, qdot), violated, message.format("(traced)", "(traced)"))
