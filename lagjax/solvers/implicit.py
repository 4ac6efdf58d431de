"""Gauss–Legendre collocation: implicit Runge–Kutta methods that are symplectic.

The s-stage Gauss–Legendre method collocates the solution at the s Gauss nodes of the
step. It has order 2s, is A-stable and symmetric, and — because its coefficients
satisfy bᵢaᵢⱼ + bⱼaⱼᵢ = bᵢbⱼ — it is symplectic for every Hamiltonian, separable or
not. That makes it the method for q-dependent mass matrices (double pendulum,
spherical coordinates, tops in Euler angles), where explicit splitting does not
apply. The price is a nonlinear system for the stages at every step, solved here
with optimistix to round-off so that the long-time energy error stays bounded.
"""

import abc
import math
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple, TypeAlias

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.flatten_util import ravel_pytree
from jaxtyping import Array

from lagjax._core.solver_kinds import (
    AbstractSymplecticRungeKutta,
    AbstractTimeReversible,
)
from lagjax.solvers.compensated import compensated_add, zero_compensation
from lagjax.solvers.stage_iteration import StageIteration


class CollocationTableau(NamedTuple):
    """Butcher tableau (A, b, c) of an implicit Runge–Kutta method with invertible A.

    Plain tuples of floats, so that a tableau is hashable and can be a static field.
    """

    a: tuple[tuple[float, ...], ...]
    b: tuple[float, ...]
    c: tuple[float, ...]

    def update_weights(self) -> np.ndarray:
        """d = bᵀA⁻¹, so that y₁ = y₀ + Σᵢ dᵢ Zᵢ from the stage increments Zᵢ."""
        return np.linalg.solve(np.array(self.a).T, np.array(self.b))

    def extrapolation(self) -> np.ndarray:
        """E with Eᵢⱼ = ℓⱼ(1 + cᵢ) − ℓⱼ(1): next step's Zᵢ ≈ Σⱼ Eᵢⱼ Zⱼ (equal steps).

        ℓⱼ are the Lagrange polynomials on the nodes {0, c₁, …, c_s}, so Σⱼ Zⱼ ℓⱼ(τ)
        is the collocation polynomial of the step minus y₀, and E evaluates it at the
        next step's nodes 1 + cᵢ relative to its end point (Hairer, Lubich & Wanner,
        §VIII.6.1). Exact for solutions that are polynomials of degree ≤ s.
        """
        nodes = np.concatenate([[0.0], self.c])

        def lagrange(j: int, tau: float) -> float:
            others = np.delete(nodes, j)
            return float(np.prod((tau - others) / (nodes[j] - others)))

        return np.array(
            [
                [lagrange(j, 1 + c_i) - lagrange(j, 1.0) for j in range(1, len(nodes))]
                for c_i in self.c
            ]
        )


_SQRT3 = math.sqrt(3.0)
_SQRT15 = math.sqrt(15.0)

# Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed., §II.1.3
# (Table 1.1 for s = 2, Table 1.2 for s = 3); Hairer & Wanner, *Solving ODEs II*,
# §IV.5, Tables 5.1 and 5.2. The one-stage method is the implicit midpoint rule.
GAUSS_LEGENDRE_1 = CollocationTableau(a=((1 / 2,),), b=(1.0,), c=(1 / 2,))
GAUSS_LEGENDRE_2 = CollocationTableau(
    a=((1 / 4, 1 / 4 - _SQRT3 / 6), (1 / 4 + _SQRT3 / 6, 1 / 4)),
    b=(1 / 2, 1 / 2),
    c=(1 / 2 - _SQRT3 / 6, 1 / 2 + _SQRT3 / 6),
)
GAUSS_LEGENDRE_3 = CollocationTableau(
    a=(
        (5 / 36, 2 / 9 - _SQRT15 / 15, 5 / 36 - _SQRT15 / 30),
        (5 / 36 + _SQRT15 / 24, 2 / 9, 5 / 36 - _SQRT15 / 24),
        (5 / 36 + _SQRT15 / 30, 2 / 9 + _SQRT15 / 15, 5 / 36),
    ),
    b=(5 / 18, 4 / 9, 5 / 18),
    c=(1 / 2 - _SQRT15 / 10, 1 / 2, 1 / 2 + _SQRT15 / 10),
)
GAUSS_LEGENDRE_TABLEAUX = {
    1: GAUSS_LEGENDRE_1,
    2: GAUSS_LEGENDRE_2,
    3: GAUSS_LEGENDRE_3,
}

# Stage equations are solved to round-off: a looser tolerance leaves an error that
# is not symplectic and shows up as a linear energy drift over long runs (Hairer,
# McLachlan & Razakarivony 2008).
STAGE_TOLERANCE = 1e-14
StageSolver: TypeAlias = optx.AbstractRootFinder | optx.AbstractFixedPointSolver
# (Kahan compensation of y, stage increments of the last step divided by its length)
_SolverState: TypeAlias = tuple[Any, Array]


def default_stage_solver() -> StageSolver:
    """Fixed-point iteration to round-off: the fastest choice for non-stiff problems."""
    return StageIteration(rtol=STAGE_TOLERANCE, atol=STAGE_TOLERANCE)


def _stage_options(root_finder: Any, y0_flat: Any) -> dict[str, Any]:
    """The state's size, capped at 1, for `StageIteration`'s absolute tolerance
    (its docstring); other root finders get no options. Capped: above 1 a looser
    stopping test would leave a non-symplectic error that drifts (the chaotic
    double pendulum's energy, `tests/test_implicit.py`)."""
    if not isinstance(root_finder, StageIteration):
        return {}
    tiny = jnp.finfo(y0_flat.dtype).tiny
    # a stopping tolerance carries no derivative (and must not, under jvp/grad)
    size = jax.lax.stop_gradient(jnp.max(jnp.abs(y0_flat)))
    return {"scale": jnp.clip(size, tiny, 1.0)}


def stage_failure_message(solver: diffrax.AbstractSolver) -> str:
    """What to tell the user when the stage equations of `solver` did not converge.

    The step reports the failure through diffrax's `RESULTS` (whose text is
    diffrax's own and cannot say why); the run's diagnosis adds this message.
    """
    name = type(solver).__name__
    # Two causes look alike from inside the step: the iteration fails both on a
    # stiff problem and where the equations of motion stop defining the motion.
    degenerate = (
        "Or the mass matrix ∂²L/∂q̇² (the Hessian ∂²H/∂p² of a Hamiltonian) became "
        "singular or degenerate along the way, where the equations of motion do not "
        "determine the acceleration (L = ½ q² q̇² at q = 0): no step size or root "
        "finder gets past that point; end the run before it (a smaller t1), or write "
        "L in coordinates where the mass matrix stays invertible. To see which, run "
        "simulate(..., throw=False) and look at the last finite states."
    )
    if isinstance(solver, AbstractGaussLegendre) and isinstance(
        solver.root_finder, StageIteration
    ):
        return (
            f"The implicit stage equations of {name} did not converge. Either the "
            "problem is stiff at this step: the default fixed-point iteration "
            "converges only while dt times the fastest frequency of the system is "
            "below about 1 (a stiff spring, a fast rotation); reduce dt, or pass "
            f"{name}(root_finder=optimistix.Newton(rtol=1e-12, atol=1e-12)), which "
            f"converges at much larger steps. {degenerate}"
        )
    return (
        f"The implicit stage equations of {name} did not converge at this step. "
        "Either the step is too large for the root finder: reduce dt, loosen the "
        "root finder's atol (round-off in the residual grows like "
        f"eps·dt·|df/dy|·|y|), or raise root_find_max_steps. {degenerate}"
    )


def _matmul(matrix: np.ndarray, x: Array) -> Array:
    """A constant coefficient matrix (rounded to x's dtype) times x, in full precision."""
    return jnp.matmul(
        jnp.asarray(matrix, dtype=x.dtype), x, precision=jax.lax.Precision.HIGHEST
    )


class _StageEquations(eqx.Module):
    """Z ↦ (Σⱼ aᵢⱼ h f(t₀ + cⱼh, y₀ + Zⱼ))ᵢ, whose fixed point is the stage increments.

    Z is an (s, n) array: row i is the increment of stage i in y's raveled
    coordinates, so a root finder sees one dense (sn × sn) Jacobian instead of a
    pytree of (sn)² tiny blocks (measured 6× faster for Newton with s = 3). Written
    as a fixed-point map so that root finders (which solve G(Z) − Z = 0) and
    fixed-point iterations both plug in.
    """

    terms: diffrax.AbstractTerm
    tableau: CollocationTableau = eqx.field(static=True)
    unravel: Callable[[Array], Any] = eqx.field(static=True)

    def __call__(self, increments: Array, inputs: tuple) -> Array:
        t0, t1, y0_flat, args, control = inputs
        slopes = [
            self.terms.vf_prod(
                t0 + c_i * (t1 - t0), self.unravel(y0_flat + z_i), args, control
            )
            for c_i, z_i in zip(self.tableau.c, increments)
        ]
        flat_slopes = jnp.stack([ravel_pytree(k)[0] for k in slopes])
        # Keep the s slopes one materialised array: otherwise XLA (CPU) may fuse
        # the vector field into the A-product, where every one of the s·n outputs
        # re-evaluates the field at all s stages. With a derived Hamiltonian vector
        # field on the double pendulum that doubled GaussLegendre(stages=2)'s step
        # (2.2× → 1.4× a hand-written twin, `benchmarks/implicit_overhead.py`).
        # The barrier changes no arithmetic, only where the kernels split.
        flat_slopes = jax.lax.optimization_barrier(flat_slopes)
        return _matmul(np.array(self.tableau.a), flat_slopes)


class AbstractGaussLegendre(
    AbstractSymplecticRungeKutta,
    AbstractTimeReversible,
    diffrax.AbstractImplicitSolver[_SolverState],
):
    r"""Engine shared by [`GaussLegendre`][] and [`ImplicitMidpoint`][].

    One step of size h solves for the stage increments Zᵢ = Yᵢ − y₀,

    $$Z_i = h \sum_{j=1}^{s} a_{ij}\, f(t_0 + c_j h,\; y_0 + Z_j), \qquad i = 1..s,$$

    with the configured optimistix solver, starting from the collocation polynomial
    of the previous step extrapolated to the new nodes (zero on the first step), and
    updates

    $$y_1 = y_0 + \sum_i d_i Z_i, \qquad d = b^\top A^{-1},$$

    which equals y₀ + h Σᵢ bᵢ f(Yᵢ) at the exact stage solution but needs no further
    evaluation of f. The update is added with Kahan compensated summation, the
    compensation carried in the solver state, so round-off does not accumulate as a
    drift. A nonlinear solve that fails (iteration limit, divergence, singular
    Jacobian) is reported through the step's `RESULTS`, never silently, and
    `stage_failure_message` says why and what to change.

    **No automatic fallback** from the fixed-point iteration to Newton: under
    `vmap` (a sweep) a fallback branch is evaluated for every member whenever one
    needs it, Newton's Jacobian and LU would be compiled into every step, and a
    step size at which the fixed-point map stops contracting (dt·ω ≳ 1) is one the
    user should choose knowingly — it under-resolves the fastest motion. The
    failure message names the remedy, `root_finder=optimistix.Newton(...)`.
    """

    term_structure: ClassVar = diffrax.AbstractTerm
    interpolation_cls: ClassVar[Callable[..., diffrax.LocalLinearInterpolation]] = (
        diffrax.LocalLinearInterpolation
    )

    @property
    @abc.abstractmethod
    def tableau(self) -> CollocationTableau:
        """The method's Butcher tableau."""

    def order(self, terms: Any) -> int:
        del terms
        return 2 * len(self.tableau.b)

    def init(self, terms: Any, t0: Any, t1: Any, y0: Any, args: Any) -> _SolverState:
        del terms, t0, t1, args
        y0_flat, _ = ravel_pytree(y0)
        stage_rates = jnp.zeros((len(self.tableau.b), y0_flat.size), y0_flat.dtype)
        return zero_compensation(y0), stage_rates

    def step(
        self,
        terms: diffrax.AbstractTerm,
        t0: Any,
        t1: Any,
        y0: Any,
        args: Any,
        solver_state: _SolverState,
        made_jump: Any,
    ) -> tuple[Any, None, dict[str, Any], _SolverState, diffrax.RESULTS]:
        # After a jump the extrapolated guess is poor but still only a guess.
        del made_jump
        compensation, previous_rates = solver_state
        y0_flat, unravel = ravel_pytree(y0)
        step_size = t1 - t0
        guess = step_size * _matmul(self.tableau.extrapolation(), previous_rates)
        solution = optx.fixed_point(
            _StageEquations(terms, self.tableau, unravel),
            self.root_finder,
            guess,
            (t0, t1, y0_flat, args, terms.contr(t0, t1)),
            options=_stage_options(self.root_finder, y0_flat),
            max_steps=self.root_find_max_steps,
            throw=False,
        )
        increments = solution.value
        update = _matmul(self.tableau.update_weights(), increments)
        y1, compensation = compensated_add(y0, unravel(update), compensation)
        safe_step_size = jnp.where(step_size == 0, 1, step_size)
        state = (compensation, increments / safe_step_size)
        result = diffrax.RESULTS.promote(solution.result)
        return y1, None, dict(y0=y0, y1=y1), state, result

    def func(self, terms: diffrax.AbstractTerm, t0: Any, y0: Any, args: Any) -> Any:
        return terms.vf(t0, y0, args)


class GaussLegendre(AbstractGaussLegendre):
    r"""The s-stage Gauss–Legendre collocation method, s = 1, 2, 3 (order 2, 4, 6).

    Symplectic for any Hamiltonian vector field — including non-separable H(q, p)
    such as a q-dependent mass matrix — symmetric (time-reversible) and A-stable;
    for a general ODE it is simply a high-order implicit Runge–Kutta method. Use it
    with `diffrax.ODETerm` on any pytree y (for Hamiltonians, y = (q, p) and the
    vector field is Hamilton's equations) and a constant step size: it provides no
    error estimate, and a symplectic method loses its long-time properties under
    naively varied steps anyway.

    ```python
    solver = lagjax.GaussLegendre(stages=3)
    sol = diffrax.diffeqsolve(diffrax.ODETerm(hamilton), solver, 0.0, 100.0, 0.01,
                              (q0, p0), stepsize_controller=diffrax.ConstantStepSize())
    ```

    **Arguments:**

    - `stages`: number of stages s ∈ {1, 2, 3}; the order is 2s.
    - `root_finder`: the optimistix solver for the stage equations. Default
      `StageIteration` (fixed-point iteration) with rtol = atol = `STAGE_TOLERANCE`
      (floored at 45 ε of the state's dtype, ≈ 5e-6 in float32): no
      Jacobian, and measured fastest on the double pendulum (4–5 iterations a step
      at h = 0.01), but it converges only while h·Lip(f) is small — beyond that the
      step reports failure (the FPU chain at hω = 1.5, say; there is no automatic
      fallback, see `AbstractGaussLegendre`). For stiff-ish problems pass
      `optimistix.Newton(rtol=1e-12, atol=1e-12)` (Jacobian
      by autodiff, LU): its stopping test needs the residual below `atol` in absolute
      terms, and round-off in the residual grows like ε·h‖∂f/∂y‖·|y|, so loosen
      `atol` accordingly (≈1e-12 for h‖∂f/∂y‖ ~ 10³). Tolerances must stay near
      round-off for long runs (and be loosened to ~1e-5 for Newton in float32).
    - `root_find_max_steps`: iterations allowed before the step is reported as failed.

    **References:**

    - E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed.,
      Springer 2006, §II.1.3 (collocation methods), §VI.4 (symplecticity),
      §VIII.6 (implementation).
    - E. Hairer, G. Wanner, *Solving Ordinary Differential Equations II*, 2nd ed.,
      Springer 1996, §IV.5 (Gauss methods) and §IV.8 (stage equations in terms of
      Zᵢ, update with d = bᵀA⁻¹).
    - E. Hairer, R. I. McLachlan, A. Razakarivony, "Achieving Brouwer's law with
      implicit Runge–Kutta methods", *BIT Numer. Math.* 48 (2008) 231–243.
    """

    stages: int = eqx.field(static=True, default=2)
    root_finder: StageSolver = eqx.field(default_factory=default_stage_solver)
    root_find_max_steps: int = eqx.field(static=True, default=30)

    def __check_init__(self):
        if self.stages not in GAUSS_LEGENDRE_TABLEAUX:
            raise ValueError(
                f"GaussLegendre(stages={self.stages!r}): stages must be 1, 2 or 3 "
                "(orders 2, 4, 6)."
            )

    @property
    def tableau(self) -> CollocationTableau:
        return GAUSS_LEGENDRE_TABLEAUX[self.stages]


class ImplicitMidpoint(AbstractGaussLegendre):
    r"""The implicit midpoint rule, y₁ = y₀ + h f(t₀ + h/2, (y₀ + y₁)/2).

    The one-stage Gauss–Legendre method (same engine as `GaussLegendre(stages=1)`):
    order 2, symplectic for every Hamiltonian, symmetric, A-stable, and it conserves
    all quadratic invariants exactly (angular momentum of a central-force problem).
    Arguments as for [`GaussLegendre`][], without `stages`.

    **References:**

    - E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed.,
      Springer 2006, §I.1.2, §II.1.3 and Theorem VI.3.5.
    """

    root_finder: StageSolver = eqx.field(default_factory=default_stage_solver)
    root_find_max_steps: int = eqx.field(static=True, default=30)

    @property
    def tableau(self) -> CollocationTableau:
        return GAUSS_LEGENDRE_1
