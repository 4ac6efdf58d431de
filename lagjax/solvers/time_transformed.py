r"""Time-transformed splitting: symplectic steps that shrink where the force is strong.

A fixed step cannot follow an orbit that spends its period far away and passes the
centre in a moment. A *Sundman transformation* $dt = g\,ds$ lets the integrator
take equal steps in a fictitious time $s$ and unequal steps in $t$; done in the
extended phase space $(q, t;\; p, p_t)$ it keeps the method symplectic.

**The extended Hamiltonian.** For $H = T(p) + V(q, t)$ with $p_t = -H(q_0, p_0)$
(minus the energy, the binding energy $B$ of a bound orbit), the logarithmic
Hamiltonian of Mikkola & Tanikawa (1999) and Preto & Tremaine (1999) generalises to

$$\Gamma(q, t, p, p_t) = f\big(T(p) + p_t\big) - f\big(-V(q, t)\big),$$

for an increasing $f$ with $f' = w > 0$, the *weight*. $\Gamma = 0$ exactly where
$H + p_t = 0$, and there Hamilton's equations of $\Gamma$ in $s$ are those of $H$
in $t$ with $dt/ds = w(-V)$ (HLW §VIII.2): $\Gamma$ is $H + p_t$ times a positive
factor on the energy shell. $\Gamma$ is separable in the extended variables, so
both halves flow exactly and explicitly:

- **drift** (the flow of $f(T + p_t)$; $p$, $p_t$ fixed):
  $q \mathrel{+}= \sigma\, w(T + p_t)\,\partial T/\partial p$,
  $t \mathrel{+}= \sigma\, w(T + p_t)$;
- **kick** (the flow of $-f(-V)$; $q$, $t$ fixed):
  $p \mathrel{-}= \sigma\, w(-V)\,\partial V/\partial q$,
  $p_t \mathrel{-}= \sigma\, w(-V)\,\partial V/\partial t$.

Any splitting table of `lagjax.solvers.splitting` composes them; the map on
$(q, t, p, p_t)$ is symplectic, and time-reversible for a palindromic table.

**The position form.** lagjax's tables are written kick first (velocity Verlet).
Here the roles of the two flows are exchanged — drift first, $D_{b_0} K_{a_1}
D_{b_1} \cdots$, position Verlet and its compositions — because only that form
keeps Kepler's orbit exact: with the logarithmic weight, e = 0.9 and 20 steps per
period, the drift-first leapfrog keeps the energy to 4e-15 and the kick-first one
to 1e-2. A splitting method's order conditions hold for any pair of flows, so
every table keeps its order with the roles exchanged; only the Runge–Kutta–Nyström
tables, which need a quadratic kinetic energy ($f(T + p_t)$ is not), are refused.

**The weight.** The default $w(x) = 1/x$ ($f = \ln$) is the logarithmic
Hamiltonian: $dt/ds = 1/(-V)$, for gravitating bodies a step proportional to the
distance. For Kepler's problem its leapfrog moves exactly on the true orbit — energy,
angular momentum and the Runge–Lenz vector are kept to round-off at any step — and
errs only in the timing along it (Mikkola & Tanikawa 1999; Preto & Tremaine 1999).
Another weight $w(x) > 0$ (say $x^{-3/2}$, stronger refinement near the centre) is
a user's function of the positive energy-like quantity $x$ ($T + p_t$ in a drift,
$-V$ in a kick; equal on the exact solution); $w(x) = 1$ is the plain splitting in
$t$. The weight must be positive at the start, so the logarithmic Hamiltonian needs
$V(q_0) < 0$ (an attractive potential, zero at infinity).

??? cite "References"

    - Mikkola & Tanikawa, *Explicit symplectic algorithms for time-transformed
      Hamiltonians*, Celest. Mech. Dyn. Astron. 74, 287 (1999).
    - Preto & Tremaine, *A class of symplectic integrators with adaptive time step
      for separable Hamiltonian systems*, Astron. J. 118, 2532 (1999).
    - Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
      Springer (2006), §VIII.2 (Sundman transformation, symplectic variable steps).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._linalg.scalar_value_and_gradient import value_and_scalar_gradient
from lagjax.solvers.extrapolation import GraggBulirschStoer
from lagjax.solvers.splitting_engine import AbstractSplittingSolver


class SeparableEnergies(Protocol):
    """What the extended terms call of a separable Hamiltonian H = T(p) + V(q, t)."""

    def kinetic_energy(self, p: Any, t: Any = 0.0, args: Any = None) -> jax.Array: ...

    def potential_energy(self, q: Any, t: Any = 0.0, args: Any = None) -> jax.Array: ...


def logarithmic_weight(x: Any) -> Any:
    """w(x) = 1/x: the logarithmic Hamiltonian, dt/ds = 1/(−V)."""
    return 1 / x


class TimeTransformed(eqx.Module):
    r"""A splitting method run in fictitious time on the extended Hamiltonian
    $\Gamma = f(T + p_t) - f(-V)$ (module docstring), with $f' = $ `weight`.

    Use it through `simulate`, with `dt` the fictitious step $ds$:

    ```python
    traj = lj.simulate(kepler, y0, t1=100.0, dt=0.05, ts=ts,
                       solver=lj.TimeTransformed(lj.Yoshida4()))
    ```

    The states are given at the physical times `ts` (default: `t1` alone): each
    save is a partial fictitious step from the last step before it, its length
    solved by the secant method so that the step ends at the save time, so saves keep
    the method's order (`lagjax._integrate.time_transformed_run`).

    **Arguments:**

    - `splitting`: any lagjax splitting solver (`StormerVerlet`, `Yoshida4`,
      `BlanesMoan6`, `KahanLi8`, …), its kick and drift tables run at the fixed
      step `dt`; or `GraggBulirschStoer(rtol=..., atol=...)`, the extrapolated
      leapfrog, whose step starts at `dt` and then follows its error estimate
      (`lagjax.solvers.extrapolation`).
    - `weight`: $w(x) > 0$ with $dt/ds = w(-V)$ on the solution; default
      $1/x$, the logarithmic Hamiltonian.
    - `precision`: `"double"` (default) or `"double-double"`: every step in
      double-double arithmetic (about 32 digits, `lagjax._linalg.double_double`),
      the states rounded to float64 only at the saves. In float64 the log
      Hamiltonian that the method keeps random-walks by round-off, about √n ε
      after n steps, and at the pericentre of an eccentric orbit the energy error
      is that walk times 2/(1 − e) (Kepler e = 0.99, 1000 periods: 3.6e-12);
      in double-double the walk is 10¹⁶ times smaller. It costs about 17× a
      float64 step, needs a splitting table (not `GraggBulirschStoer`) and
      T and V made of rational arithmetic and square roots (gravitation, springs).
    """

    splitting: AbstractSplittingSolver | GraggBulirschStoer
    weight: Callable[[Any], Any] = logarithmic_weight
    precision: str = eqx.field(default="double", static=True)

    @property
    def name(self) -> str:
        return f"TimeTransformed({type(self.splitting).__name__})"

    def __check_init__(self):
        if not isinstance(
            self.splitting, (AbstractSplittingSolver, GraggBulirschStoer)
        ):
            raise TypeError(
                "TimeTransformed wraps a lagjax splitting solver (StormerVerlet, "
                "Yoshida4, BlanesMoan6, …) or GraggBulirschStoer; got "
                f"{type(self.splitting).__name__}"
            )
        if self.precision not in ("double", "double-double"):
            raise ValueError(
                "TimeTransformed: precision is 'double' or 'double-double', got "
                f"{self.precision!r}"
            )
        if self.precision == "double-double" and isinstance(
            self.splitting, GraggBulirschStoer
        ):
            raise ValueError(
                "TimeTransformed(precision='double-double') runs a splitting table "
                "(StormerVerlet, Yoshida4, KahanLi8, ...); GraggBulirschStoer's "
                "step control is float64 only"
            )
        if self.splitting.needs_quadratic_kinetic:
            raise ValueError(
                f"{type(self.splitting).__name__} is a Runge–Kutta–Nyström method: "
                "its order needs a quadratic kinetic energy, and the time-transformed "
                "f(T + p_t) is not quadratic. Use BlanesMoan6, Yoshida6 or KahanLi8"
            )

    def terms(self, system: SeparableEnergies) -> tuple[Any, Any]:
        """The splitting engine's (first, second) terms on the extended state
        ((p, p_t), (q, t)): the roles exchanged, so its kick–drift tables run
        drift first (module docstring, *the position form*)."""
        return (
            diffrax.ODETerm(ExtendedKick(system, self.weight)),
            diffrax.ODETerm(ExtendedDrift(system, self.weight)),
        )


def _times(factor: Any, tree: Any) -> Any:
    return jax.tree_util.tree_map(lambda x: (factor * x).astype(x.dtype), tree)


class ExtendedDrift(eqx.Module):
    """d(q, t)/ds = w(T + p_t) (∂T/∂p, 1), a function of the momenta (p, p_t)."""

    system: SeparableEnergies
    weight: Callable[[Any], Any]

    def __call__(self, s: Any, momenta: tuple[Any, Any], args: Any) -> Any:
        p, p_t = momenta
        # T is autonomous (a t-dependent T would make Γ non-separable).
        kinetic, (velocity,) = value_and_scalar_gradient(
            lambda p: self.system.kinetic_energy(p, 0.0, args), p
        )
        rate = self.weight(kinetic + p_t)
        return _times(rate, velocity), jnp.asarray(rate, dtype=p_t.dtype)


class ExtendedKick(eqx.Module):
    """d(p, p_t)/ds = −w(−V) (∂V/∂q, ∂V/∂t), a function of the positions (q, t)."""

    system: SeparableEnergies
    weight: Callable[[Any], Any]

    def __call__(self, s: Any, positions: tuple[Any, Any], args: Any) -> Any:
        q, t = positions
        potential, (dv_dq, dv_dt) = value_and_scalar_gradient(
            lambda q, t: self.system.potential_energy(q, t, args), q, t
        )
        rate = -self.weight(-potential)
        return _times(rate, dv_dq), jnp.asarray(rate * dv_dt, dtype=t.dtype)


def extended_state(
    system: SeparableEnergies, y0: tuple[Any, Any], t0: Any, args: Any
) -> tuple[tuple[Any, Any], tuple[Any, Any]]:
    """((p, p_t), (q, t)) at the start, with p_t = −H(q0, p0, t0): momenta first,
    as the splitting engine runs the position form (`TimeTransformed.terms`)."""
    q0, p0 = y0
    dtype = jnp.result_type(*jax.tree_util.tree_leaves(y0))
    energy = system.kinetic_energy(p0, t0, args) + system.potential_energy(q0, t0, args)
    t0 = jnp.asarray(t0, dtype=dtype)
    return (p0, jnp.asarray(-energy, dtype=dtype)), (q0, t0)


@eqx.filter_jit
def start_weights(
    solver: TimeTransformed, system: SeparableEnergies, y0: Any, t0: Any, args: Any
) -> tuple[jax.Array, jax.Array]:
    """(w(−V(q0, t0)), w(−2E)): dt/ds at the start, which must be positive and
    finite, and on a bound orbit's average (virial theorem: ⟨−V⟩ = −2E for a
    Kepler orbit; NaN where E ≥ 0). Compiled: evaluated op by op, a pair
    potential took a third of a short run's time (one dispatch per operation)."""
    q0, p0 = y0
    potential = system.potential_energy(q0, t0, args)
    energy = system.kinetic_energy(p0, t0, args) + potential
    mean = jnp.where(energy < 0, solver.weight(jnp.abs(2 * energy)), jnp.nan)
    return solver.weight(-potential), mean
