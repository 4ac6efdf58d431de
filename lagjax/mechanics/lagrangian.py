r"""`Lagrangian`: a user's $L(q, \dot q, t)$ and everything derived from it.

The user writes L as a plain JAX function of `(q, qdot)`, `(q, qdot, t)` or
`(q, qdot, t, args)`; `q` may be a scalar, an array or any pytree, with `qdot` of the
same structure. Non-conservative effects enter through a generalized force
$Q(q, \dot q, t, \text{args})$ and a Rayleigh dissipation function
$D(\dot q)$ (or $D(q, \dot q, t, \text{args})$), giving

$$ \frac{d}{dt}\frac{\partial L}{\partial \dot q} - \frac{\partial L}{\partial q}
   = Q - \frac{\partial D}{\partial \dot q}. $$

References: the course text §3 (Lagrange's equations; eq. 3.35 with generalized
forces; velocity-dependent potentials), Goldstein, *Classical Mechanics* §1.4–1.6, §2.7.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

from lagjax._core.precision import cast_floats
from lagjax._core.solver_kinds import DefaultMethod
from lagjax._core.system import AbstractSystem
from lagjax._core.terms import RattleTerm
from lagjax._linalg.singular_verdicts import singular_check as singular_check
from lagjax.mechanics.captured_globals import (
    captured_identity,
    warn_captured_numbers,
)
from lagjax.mechanics.constraints import (
    Constraints,
    constrained_motion,
    refuse_start_off_constraints,
)
from lagjax.mechanics.declared_structure import check_declared_quadratic
from lagjax.mechanics.euler_lagrange import euler_lagrange_acceleration
from lagjax.mechanics.functions import as_system_function
from lagjax.mechanics.lagrangian_integration import lagrangian_integration
from lagjax.mechanics.legendre import tree_dot
from lagjax.mechanics.legendre_hamiltonian import LegendreHamiltonian
from lagjax.mechanics.network_formulation import (
    holds_network,
    network_euler_lagrange_acceleration,
)
from lagjax.mechanics.scalar_constraints import (
    scalar_constrained_motion,
    scalar_constraints_apply,
)
from lagjax.mechanics.signature import (
    call_with_arity,
    check_same_structure,
    check_scalar,
    positional_arity,
)


def refuse_no_coordinates(q: Any) -> None:
    """q must hold at least one number: with none there is no motion to derive, and
    the mass-matrix solve has nothing to factor (checked on shapes: free under jit)."""
    leaves = jax.tree_util.tree_leaves(q)
    if sum(jnp.size(leaf) for leaf in leaves) == 0:
        shapes = [jnp.shape(leaf) for leaf in leaves]
        raise ValueError(
            f"q has no coordinates (shape {shapes[0] if len(shapes) == 1 else shapes}"
            "): a system needs at least one; pass q with one entry per coordinate, "
            "e.g. jnp.array([0.1]) for one (an empty array often comes from slicing "
            "or from jnp.zeros(n) with n = 0)"
        )


class Lagrangian(AbstractSystem):
    r"""A mechanical system given by its Lagrangian $L(q, \dot q, t)$.

    **Arguments:**
    - `L`: `L(q, qdot)`, `L(q, qdot, t)` or `L(q, qdot, t, args)` returning a scalar.
    - `force`: optional generalized non-conservative force `Q(q, qdot[, t[, args]])`,
      a pytree like `q`.
    - `dissipation`: optional Rayleigh function `D(qdot)` or `D(q, qdot[, t[, args]])`;
      contributes $-\partial D/\partial\dot q$ to the generalized force.
    - `quadratic_in_velocity`: declare that L is at most quadratic in q̇
      ($\tfrac12\dot q^T M(q)\dot q + a(q)\cdot\dot q - V(q)$). The Legendre transform
      is then one linear solve instead of a Newton iteration.
    - `constraints`: optional holonomic constraint `g(q[, t[, args]]) = 0` (scalar or
      1-D array), or a `Constraints` object (also nonholonomic ones). `acceleration`
      then includes the constraint forces; `multipliers` and `constraint_force`
      give them (see `lagjax.mechanics.constraints`).
    - `formulation`: how `acceleration` derives q̈. `"closed_form"`:
      `euler_lagrange_acceleration` (scalar arithmetic up to six coordinates — the
      speed of hand-written equations for a formula L — dense above). `"network"`:
      one gradient and n + 1 Hessian–vector products
      (`lagjax.mechanics.network_formulation`), the fewest passes through an L
      whose cost is its matrix products. `"auto"` (default) picks `"network"` when
      L is an equinox Module with floating array leaves (a neural network, or any
      Module with trainable arrays), else `"closed_form"`.

    `t` defaults to 0.0 and `args` to None in every method.

    **What is compiled, and when.** `simulate` compiles L once and reuses the
    program for every later run of the same system: numbers L reads from module
    globals (`g = 9.81` used inside L) are frozen at their value of the first run,
    and rebinding them later silently changes nothing for this `Lagrangian` object.
    Their values at construction are part of the system's identity (the static
    field `captured`), so a `Lagrangian(L)` built after the rebinding compiles anew
    and reads the new value. Pass numbers
    that vary through `args` (`L(q, qdot, t, args)`, `simulate(..., args=...)`),
    which are traced: a new value reuses the compilation. A `CapturedNumberWarning`
    is raised here when L (or `force`, `dissipation`) reads a module-level number
    whose name is not UPPER_CASE (`lagjax.mechanics.captured_globals`).
    """

    function: Callable = eqx.field(converter=as_system_function)
    arity: int = eqx.field(static=True)
    force: Callable | None = eqx.field(converter=as_system_function)
    force_arity: int = eqx.field(static=True)
    dissipation: Callable | None = eqx.field(converter=as_system_function)
    dissipation_arity: int = eqx.field(static=True)
    quadratic_in_velocity: bool = eqx.field(static=True)
    constraints: Constraints | None
    formulation: str = eqx.field(static=True)
    # The module-level numbers L, Q and D read, as built (`captured_identity`).
    captured: tuple = eqx.field(static=True)

    def __init__(
        self,
        L: Callable,
        *,
        force: Callable | None = None,
        dissipation: Callable | None = None,
        quadratic_in_velocity: bool = False,
        constraints: Callable | Constraints | None = None,
        formulation: str = "auto",
    ):
        self.function = L
        self.arity = positional_arity(L, minimum=2, maximum=4, what="the Lagrangian L")
        self.captured = captured_identity(
            warn_captured_numbers(L, "the Lagrangian L"),
            warn_captured_numbers(force, "the force Q"),
            warn_captured_numbers(dissipation, "the dissipation function D"),
        )
        self.force = force
        self.force_arity = (
            0
            if force is None
            else positional_arity(force, minimum=2, maximum=4, what="the force Q")
        )
        self.dissipation = dissipation
        self.dissipation_arity = (
            0
            if dissipation is None
            else positional_arity(
                dissipation, minimum=1, maximum=4, what="the dissipation function D"
            )
        )
        self.quadratic_in_velocity = quadratic_in_velocity
        if constraints is not None and not isinstance(constraints, Constraints):
            constraints = Constraints(holonomic=constraints)
        self.constraints = constraints
        if formulation not in ("auto", "closed_form", "network"):
            raise ValueError(
                "formulation is 'auto', 'closed_form' or 'network'; got "
                f"{formulation!r}"
            )
        if formulation == "auto":
            formulation = "network" if holds_network(L) else "closed_form"
        self.formulation = formulation

    def __call__(self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        """The value of L."""
        check_same_structure(q, qdot, "q", "qdot")
        value = call_with_arity(self.function, self.arity, q, qdot, t, args)
        return check_scalar(value, "the Lagrangian L")

    def generalized_force(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None
    ) -> Any | None:
        """Q − ∂D/∂q̇, or None when the system has neither."""
        total = None
        if self.force is not None:
            total = call_with_arity(self.force, self.force_arity, q, qdot, t, args)
            check_same_structure(q, total, "q", "the force Q")
        if self.dissipation is not None:
            friction = jax.grad(self._dissipation_value, argnums=1)(q, qdot, t, args)
            friction = jax.tree_util.tree_map(jnp.negative, friction)
            total = (
                friction
                if total is None
                else jax.tree_util.tree_map(jnp.add, total, friction)
            )
        return total

    def _dissipation_value(self, q, qdot, t, args):
        assert self.dissipation is not None
        if self.dissipation_arity == 1:
            value = self.dissipation(qdot)
        else:
            value = call_with_arity(
                self.dissipation, self.dissipation_arity, q, qdot, t, args
            )
        return check_scalar(value, "the dissipation function D")

    def acceleration(
        self,
        q: Any,
        qdot: Any,
        t: Any = 0.0,
        args: Any = None,
        *,
        check: bool | str | None = None,
    ) -> Any:
        """q̈ from the Euler–Lagrange equations (see `euler_lagrange_acceleration`).

        A singular mass matrix — or, with constraints, a singular saddle-point
        matrix (redundant or degenerate constraints) — is never a finite wrong
        number. By default (`check` None) a call on concrete values raises a
        clear error, and a call under a trace — inside `jit`, `vmap` or an
        integration loop — returns NaN instead, a test that costs one fused
        select rather than a branch that splits the step (hand-written speed;
        `benchmarks/derivation_overhead.py`); check the loop's result once, as
        `simulate` does. `check=True` raises also under
        `jit` (`eqx.error_if`, at a branch per call), `"nan"` always poisons,
        `False` skips the test (an exactly singular matrix still gives inf/NaN).
        """
        check_same_structure(q, qdot, "q", "qdot")
        refuse_no_coordinates(q)
        check = singular_check(check, q, qdot, t)
        self(q, qdot, t, args)  # trace-time checks of L's output; no run-time cost
        if self.constraints is None:
            return self._free_acceleration(q, qdot, t, args, check=check)
        return self._constrained_motion(q, qdot, t, args, check=check)[0]

    def multipliers(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None
    ) -> jax.Array:
        """Lagrange multipliers λ (holonomic rows first) of a constrained system."""
        return self._constrained_motion(q, qdot, t, args)[1]

    def constraint_force(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None
    ) -> Any:
        """The generalized constraint force Aᵀλ (structure of `q`)."""
        return self._constrained_motion(q, qdot, t, args)[2]

    def _constrained_motion(self, q, qdot, t, args, *, check: bool | str = True):
        """(q̈, λ, Aᵀλ): in scalar form for a few coordinates, else dense."""
        if self.constraints is None:
            raise ValueError("this Lagrangian has no constraints")
        check_same_structure(q, qdot, "q", "qdot")
        refuse_no_coordinates(q)
        if scalar_constraints_apply(self, q):
            force = self.generalized_force(q, qdot, t, args)
            return scalar_constrained_motion(
                self._call_unchecked, self.constraints, q, qdot, t, args, force,
                check=check,
            )  # fmt: skip
        free = self._free_acceleration(q, qdot, t, args, check=check)
        return constrained_motion(self, q, qdot, t, args, free, check=check)

    def _free_acceleration(self, q, qdot, t, args, *, check):
        """q̈ without constraint forces, by this Lagrangian's `formulation`."""
        derive = (
            network_euler_lagrange_acceleration
            if self.formulation == "network"
            else euler_lagrange_acceleration
        )
        force = self.generalized_force(q, qdot, t, args)
        return derive(self._call_unchecked, q, qdot, t, args, force, check=check)

    def _call_unchecked(self, q, qdot, t, args):
        return call_with_arity(self.function, self.arity, q, qdot, t, args)

    def momentum(self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None) -> Any:
        """Canonical momentum p = ∂L/∂q̇ (structure of `q`)."""
        return jax.grad(self, argnums=1)(q, qdot, t, args)

    def mass_matrix(
        self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None
    ) -> jax.Array:
        """∂²L/∂q̇∂q̇ as an (n, n) matrix in the raveled (flat) coordinates of q."""
        check_same_structure(q, qdot, "q", "qdot")
        v_flat, unravel = ravel_pytree(qdot)
        return jax.hessian(lambda v: self(q, unravel(v), t, args))(v_flat)

    def energy(self, q: Any, qdot: Any, t: Any = 0.0, args: Any = None) -> jax.Array:
        """Jacobi's integral h = q̇·∂L/∂q̇ − L (the energy when L = T − V, T quadratic)."""
        return tree_dot(qdot, self.momentum(q, qdot, t, args)) - self(q, qdot, t, args)

    def to_hamiltonian(self) -> LegendreHamiltonian:
        """The Legendre-transformed Hamiltonian H(q, p, t) = p·q̇ − L."""
        return LegendreHamiltonian(self)

    # -- AbstractSystem: how the loop integrates a Lagrangian ---------------------

    @property
    def second_is_momentum(self) -> bool:
        return False

    def default_method(self, dt: Any) -> DefaultMethod:
        """Gauss–Legendre (2 stages: implicit, symplectic, order 4) with `dt`, else
        adaptive `Tsit5`; with constraints, `Tsit5` (projected onto them)."""
        if self.constraints is not None or dt is None:
            return DefaultMethod.ADAPTIVE
        return DefaultMethod.SYMPLECTIC_RUNGE_KUTTA

    def keeps_constraints(self) -> bool:
        return self.constraints is not None

    def accepted_terms(self) -> tuple[type, ...]:
        return () if self.constraints is None else (RattleTerm,)

    def check_start(self, y0: Any, t0: Any, args: Any, dtype: Any) -> None:
        """A declared `quadratic_in_velocity` must hold at the start, and a
        constrained Lagrangian's start must lie on its constraints.

        Checked before the run, on concrete values in the run's `dtype`: the
        compiled run sees traced values and could only attach the error at run
        time, without the residuals in the message.
        """
        if not self.quadratic_in_velocity and self.constraints is None:
            return  # nothing to check: no conversion (an eager op) either
        q0, qdot0 = cast_floats(tuple(y0), dtype)
        if self.quadratic_in_velocity:
            check_declared_quadratic(
                lambda fixed, v: self(fixed[0], v, *fixed[1:]),
                (q0, t0, cast_floats(args, dtype)),
                qdot0,
                key=self.function,
                flag="quadratic_in_velocity",
                what="L as a function of q̇",
            )
        if self.constraints is None:
            return
        constraints = cast_floats(self.constraints, dtype)
        refuse_start_off_constraints(
            constraints, q0, qdot0, t0, cast_floats(args, dtype)
        )

    def state_rate(self, q: Any, second: Any, t: Any, args: Any) -> tuple[Any, Any]:
        return second, self.acceleration(q, second, t, args)

    def phase_space_obstacle(self) -> str | None:
        if self.constraints is None:
            return None
        return (
            "A constrained Lagrangian moves on a submanifold, and tangent vectors off "
            "it would add spurious exponents: write L in independent coordinates."
        )

    def integration(self, solver: Any, y0: Any, t0: Any, args: Any) -> Any:
        """(q, q̇) with the Euler–Lagrange vector field for general solvers; (q, p)
        of the Legendre transform for symplectic ones (and L itself for variational
        ones, the constraints for RATTLE): `lagjax.mechanics.lagrangian_integration`."""
        return lagrangian_integration(self, self.to_hamiltonian, solver, y0, t0, args)

    def state_velocity(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return second

    def state_momentum(self, q: Any, second: Any, t: Any, args: Any) -> Any:
        return self.momentum(q, second, t, args)

    def state_energy(self, q: Any, second: Any, t: Any, args: Any) -> jax.Array:
        return self.energy(q, second, t, args)

    def path_lagrangian(self) -> Lagrangian:
        return self

    def conserves_energy_if_autonomous(self) -> bool:
        return (
            self.force is None and self.dissipation is None and self.constraints is None
        )
