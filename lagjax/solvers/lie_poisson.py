r"""Structure-preserving solvers for rigid bodies: Lie–Poisson splitting.

The free rigid body's energy $T = \sum_i \Pi_i^2 / 2I_i$ is a sum of exactly
solvable pieces. A piece $c_i\Pi_i^2/2$ keeps $\Pi_i$ fixed and turns the body about
its own axis $e_i$ at the constant rate $c_i\Pi_i$: over a time $\tau$ the body
turns by $\alpha = \tau\,c_i\Pi_i$,

$$ q \mapsto q \otimes \left(\cos\tfrac\alpha2,\ e_i \sin\tfrac\alpha2\right),
   \qquad \boldsymbol\Pi \mapsto \exp(-\alpha\,\hat e_i)\,\boldsymbol\Pi, $$

so the space angular momentum $R\boldsymbol\Pi$ does not change at all. Two splits
of $T$ into such flows give the free-body *drift* $\mathcal D_\tau$:

- `free_body="symmetric-top"` (the default; Touma & Wisdom 1994): with the median
  moment $I_r$ as reference,
  $T = |\boldsymbol\Pi|^2/2I_r + \sum_i c_i\Pi_i^2/2$, $c_i = 1/I_i - 1/I_r$.
  The first term is a Casimir of the Lie–Poisson bracket: its flow $\mathcal I$
  keeps $\boldsymbol\Pi$ and turns the body about $\boldsymbol\Pi/|\boldsymbol\Pi|$
  by $\tau|\boldsymbol\Pi|/I_r$, and it commutes exactly with the flow of every
  function of $\boldsymbol\Pi$. $c$ vanishes on the median axis, so
  $\mathcal D_\tau = \mathcal I(\tau)\,\mathcal R_a(\tfrac\tau2)\,
  \mathcal R_b(\tau)\,\mathcal R_a(\tfrac\tau2)$, with $a$ and $b$ the axes of the
  smallest and the largest moment. For a symmetric body a second $c_i$ vanishes:
  $\mathcal D_\tau$ is then the exact flow of the free symmetric top, whatever τ.
- `free_body="axes"` (McLachlan 1993; Reich 1994): $c_i = 1/I_i$ on every axis,
  $\mathcal D_\tau = \mathcal R_1(\tfrac\tau2)\,\mathcal R_2(\tfrac\tau2)\,
  \mathcal R_3(\tau)\,\mathcal R_2(\tfrac\tau2)\,\mathcal R_1(\tfrac\tau2)$.

Either is an explicit, time-reversible, order-2 Lie–Poisson integrator: each factor
is an exact rotation, so $|\boldsymbol\Pi|$ and the space $\mathbf L$ are kept to
round-off and the energy error stays bounded. A potential $V(R)$ (the heavy top's
gravity) adds the *kick* $\mathcal K_\tau: \boldsymbol\Pi \mapsto \boldsymbol\Pi +
\tau\,\boldsymbol\tau(R)$ — exact, because the torque depends on the orientation
alone — and a step is the symmetric kick–drift–kick
$\mathcal K_{h/2}\,\mathcal D_h\,\mathcal K_{h/2}$ (for a free body the kicks
vanish). Higher orders come from symmetric compositions of that step (Yoshida's
triple jump for order 4), with adjacent half-kicks merged as in
`lagjax.solvers.splitting`.

Within a step the rotations are accumulated as an increment of the quaternion,
$q_1 = q_0 \otimes (1 + \delta)$, and of the momentum, $\Delta\boldsymbol\Pi$; both
stay small and keep their low-order bits, and meet the state once per step through
Kahan's compensated sum (`lagjax.solvers.compensated`).

`QuaternionProjection` is the baseline instead: any diffrax solver (Tsit5,
Dopri8, …) on the rigid body's vector field, with the quaternion projected back to
unit length after every step.

??? cite "References"

    - McLachlan, *Explicit Lie–Poisson integration and the Euler equations*,
      Phys. Rev. Lett. 71, 3043 (1993).
    - Reich, *Momentum conserving symplectic integrators*, Physica D 76, 375 (1994).
    - Touma & Wisdom, *Lie–Poisson integrators for rigid body dynamics in the solar
      system*, Astron. J. 107, 1189 (1994).
    - Dullweber, Leimkuhler & McLachlan, *Symplectic splitting methods for rigid
      body molecular dynamics*, J. Chem. Phys. 107, 5840 (1997).
    - Yoshida, *Construction of higher order symplectic integrators*, Phys. Lett. A
      150, 262 (1990).
    - Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
      Springer (2006), §VII.5.
"""

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from diffrax import RESULTS, LocalLinearInterpolation

from lagjax._core.solver_kinds import AbstractTimeReversible
from lagjax._core.terms import RigidBodyTerm, physical_step
from lagjax.rigid.quaternion import quaternion_multiply
from lagjax.solvers.compensated import add_to_state, zero_compensation
from lagjax.solvers.projection import AbstractProjectedSolver

# The composition tables and the kick merging are those of the canonical splitting
# methods: one source for Yoshida's triple jump.
from lagjax.solvers.splitting_tables import YOSHIDA4_WEIGHTS, merged_kicks

if TYPE_CHECKING:
    from typing import ClassVar as AbstractClassVar
    from typing import ClassVar as AbstractVar
else:
    from equinox import AbstractClassVar, AbstractVar

# Compensation for (quaternion, body momentum), or None when not compensated.
_RigidState = Any

# The free-body drift D_τ of each split: rows (axis, fraction of τ) in order of
# application. "axes" (McLachlan) names body axes, each turned at the rate Π_i/I_i;
# "symmetric-top" names axes by the rank of their moment (0 the smallest, 2 the
# largest), each turned at Π_i (1/I_i − 1/I_r), plus one isotropic turn. The other
# way round (largest outside) measured within 3× of this, better or worse by body.
_FREE_BODY_SPLITS = {
    "axes": ((0, 0.5), (1, 0.5), (2, 1.0), (1, 0.5), (0, 0.5)),
    "symmetric-top": ((0, 0.5), (2, 1.0), (0, 0.5)),
}


def _cyclic(v: jax.Array, start) -> jax.Array:
    """$(v_s, v_{s+1}, v_{s+2})$, indices mod 3, for a traced `start`.

    A window of $[v, v]$: a permutation, so exact. With it one rotation serves
    every axis, and the axis can be loop data instead of Python code.
    """
    return jax.lax.dynamic_slice_in_dim(jnp.concatenate([v, v]), start, 3)


def _turn_about_axis(axis, tau, rate, momentum, delta):
    r"""The exact flow of $c_i\,\Pi_i^2/2$ for a time τ, on increments.

    The body turns about its axis $e_i$ by $\alpha = \tau\,c_i\Pi_i$, with the
    rate coefficient $c_i$ = `rate` ($1/I_i$, or $1/I_i - 1/I_r$ for the residual
    of the symmetric-top split). `momentum` is the current Π, shape (3,), and
    `delta` the quaternion increment, shape (4,), with q = q₀ ⊗ (1 + δ); `axis`
    may be traced. Returns the change of Π and the new δ. Vectors are taken in the
    cyclic order (i, j, k) that starts at the axis and turned back after. Versines
    are formed as 2 sin²(x/2), not 1 − cos x, to keep their bits.
    """
    m = _cyclic(momentum, axis)
    angle = tau * rate * m[0]
    sin_angle = jnp.sin(angle)
    versine = 2 * jnp.sin(0.5 * angle) ** 2
    # Π turns by −α about e_i.
    change_j = -versine * m[1] + sin_angle * m[2]
    change_k = -sin_angle * m[1] - versine * m[2]
    # (1 + δ) ⊗ (1 + ρ) with ρ = (cos(α/2) − 1, e_i sin(α/2)).
    rho_w = -2 * jnp.sin(0.25 * angle) ** 2
    rho_v = jnp.sin(0.5 * angle)
    w, v = delta[0], _cyclic(delta[1:], axis)
    new_v = jnp.stack(
        [
            v[0] + rho_v + w * rho_v + rho_w * v[0],
            v[1] + rho_w * v[1] + rho_v * v[2],
            v[2] + rho_w * v[2] - rho_v * v[1],
        ]
    )
    new_w = w + rho_w + w * rho_w - rho_v * v[0]
    back = (3 - axis) % 3  # the inverse permutation
    change = _cyclic(jnp.stack([jnp.zeros_like(change_j), change_j, change_k]), back)
    return change, jnp.concatenate([new_w[None], _cyclic(new_v, back)])


def _turn_isotropically(tau, rate, momentum, delta):
    r"""The exact flow of $|\boldsymbol\Pi|^2/2I_r$ for a time τ, on δ.

    A Casimir's flow: Π stays, and the body turns about $n = \Pi/|\Pi|$ by
    $\alpha = \tau|\Pi|/I_r$, `rate` = $1/I_r$. Returns the new δ. The axis is
    never formed: $n\sin\tfrac\alpha2 = \Pi\,\tfrac{\tau}{2I_r}
    \operatorname{sinc}\tfrac\alpha2$, which holds down to Π = 0.
    """
    squared = jnp.sum(momentum**2)
    positive = squared > 0
    # The double `where` keeps the gradient finite at Π = 0, where |Π| has none.
    norm = jnp.where(positive, jnp.sqrt(jnp.where(positive, squared, 1)), 0)
    half_angle = 0.5 * tau * rate * norm
    rho_v = (0.5 * tau * rate * jnp.sinc(half_angle / jnp.pi)) * momentum
    rho_w = -2 * jnp.sin(0.5 * half_angle) ** 2  # cos(α/2) − 1, to the last bit
    # (1 + δ) ⊗ (1 + ρ) − 1, ρ = (ρ_w, ρ_v).
    w, v = delta[0], delta[1:]
    new_w = w + rho_w + w * rho_w - jnp.dot(v, rho_v)
    new_v = v + rho_v + w * rho_v + rho_w * v + jnp.cross(v, rho_v)
    return jnp.concatenate([new_w[None], new_v])


def _drift_rates(split, moments, dtype):
    """(axes, rate coefficients, isotropic rate or None) of one split's drift.

    For "symmetric-top", $I_r$ is the median moment: the repeated moment of a
    symmetric body, oblate or prolate, so that one residual rate is exactly 0 and
    the drift is the body's exact flow.
    """
    ranks = jnp.asarray([axis for axis, _ in _FREE_BODY_SPLITS[split]])
    inverse = 1 / moments.astype(dtype)
    if split == "axes":
        return ranks, inverse[ranks], None
    order = jnp.argsort(moments)
    isotropic = inverse[order[1]]
    axes = order[ranks]
    return axes, inverse[axes] - isotropic, isotropic


def _stage_table(weights, dtype):
    """Rows (weight, kick before the drift, clock at the kick) of a composition of
    kick–drift–kick steps with adjacent kicks merged, and the closing kick."""
    kicks = merged_kicks(weights)
    clocks = [sum(weights[:stage]) for stage in range(len(weights))]
    return jnp.asarray([weights, kicks[:-1], clocks], dtype=dtype).T, kicks[-1]


class AbstractRigidBodySplitting(
    AbstractTimeReversible, diffrax.AbstractSolver[_RigidState]
):
    r"""Kick–drift–kick Lie–Poisson splitting, composed with weights $\gamma_s$.

    One step of size h is $\prod_s \mathcal K_{\gamma_s h/2}\,
    \mathcal D_{\gamma_s h}\,\mathcal K_{\gamma_s h/2}$ with adjacent kicks merged;
    the kicks see the time the drifts before them have reached. Fixed step only.
    Needs the term `RigidBodyTerm(body)` and the state `(quaternion, body_momentum)`.
    """

    composition_weights: AbstractClassVar[tuple[float, ...]]
    nominal_order: AbstractClassVar[int]
    compensated: AbstractVar[bool]
    free_body: AbstractVar[str]

    term_structure: ClassVar = RigidBodyTerm
    interpolation_cls: ClassVar[Callable[..., LocalLinearInterpolation]] = (
        LocalLinearInterpolation
    )

    def __check_init__(self):
        weights = self.composition_weights
        if abs(sum(weights) - 1) > 1e-13 or list(weights) != list(reversed(weights)):
            raise ValueError(
                f"composition weights {weights} must be a palindrome summing to 1"
            )
        if self.free_body not in _FREE_BODY_SPLITS:
            raise ValueError(
                f"free_body must be one of {sorted(_FREE_BODY_SPLITS)}, "
                f"got {self.free_body!r}"
            )

    def order(self, terms: Any) -> int:
        return self.nominal_order

    def init(self, terms, t0, t1, y0, args) -> _RigidState:
        return zero_compensation(y0) if self.compensated else None

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del made_jump  # nothing is carried between steps but round-off
        term, start, h = physical_step(terms, RigidBodyTerm, t0, t1)
        q0, momentum0 = y0
        delta, change = self._increments(term.body, start, h, q0, momentum0, args)
        compensation_q, compensation_p = solver_state or (None, None)
        q1, compensation_q = add_to_state(
            q0, quaternion_multiply(q0, delta), compensation_q
        )
        momentum1, compensation_p = add_to_state(momentum0, change, compensation_p)
        if solver_state is not None:
            solver_state = (compensation_q, compensation_p)
        y1 = (q1, momentum1)
        return y1, None, dict(y0=y0, y1=y1), solver_state, RESULTS.successful

    def _increments(self, body, start, h, q0, momentum0, args):
        """(δ, ΔΠ) of one step, shapes (4,) and (3,).

        Two nested `lax.scan`s: over the stages of the composition and, within a
        stage, over its axis rotations, with the axis as data. XLA on CPU
        compiles a loop whose body reads and writes less than 1 kB (its default
        small-while-loop threshold) into a single kernel; one rotation fits, a
        whole step does not, and straight-line code then dispatches every fused
        piece of it on its own. Measured inside `lj.simulate` (10⁵ steps, 2 cores,
        McLachlan's split): 2× faster per RigidBodyVerlet step and 6× per
        RigidBodyYoshida4 step than the same arithmetic written out (and 3.6× and
        1.3× vmapped over 1024 bodies); unrolled stages were slower still (170 μs
        a Yoshida4 step). The isotropic turn of the symmetric-top split stays out
        of the inner loop: once per stage, or once per step without kicks.
        """

        def kick(change, delta, coefficient, clock):
            q_now = q0 + quaternion_multiply(q0, delta)
            torque = body.torque(q_now, start + clock * h, args)
            return change + coefficient * h * torque

        def rotation(carry, row):
            change, delta = carry
            tau_over_h, axis, rate = row
            turn, delta = _turn_about_axis(
                axis, tau_over_h * h, rate, momentum0 + change, delta
            )
            return (change + turn, delta), None

        def stage(carry, coefficients):
            change, delta = carry
            weight, kick_coefficient, clock = coefficients
            if body.potential is not None:
                change = kick(change, delta, kick_coefficient, clock)
            rows = (weight * fractions, axes, rates)
            change, delta = jax.lax.scan(rotation, (change, delta), rows)[0]
            if isotropic is not None and body.potential is not None:
                # It commutes with the rotations: once per drift, for all of it.
                momentum = momentum0 + change
                delta = _turn_isotropically(weight * h, isotropic, momentum, delta)
            return (change, delta), None

        # Coefficients in the state's precision, so a float32 run stays float32.
        dtype = jnp.result_type(q0, momentum0)
        axes, rates, isotropic = _drift_rates(self.free_body, body.moments, dtype)
        fractions = jnp.asarray(
            [f for _, f in _FREE_BODY_SPLITS[self.free_body]], dtype=dtype
        )
        table, last_kick = _stage_table(self.composition_weights, dtype)
        carry = (jnp.zeros_like(h * momentum0), jnp.zeros_like(h * q0))
        (change, delta), _ = jax.lax.scan(stage, carry, table)
        if body.potential is not None:
            change = kick(change, delta, last_kick, 1.0)
        elif isotropic is not None:
            # Without kicks it commutes with the whole step: once for all drifts.
            delta = _turn_isotropically(h, isotropic, momentum0 + change, delta)
        return delta, change

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


class RigidBodyVerlet(AbstractRigidBodySplitting):
    r"""Order-2 Lie–Poisson splitting: $\mathcal K_{h/2}\,\mathcal D_h\,
    \mathcal K_{h/2}$, with $\mathcal D$ the symmetric free-body rotations.

    For a free body this is Touma & Wisdom's (1994) or, with `free_body="axes"`,
    McLachlan's (1993) explicit Lie–Poisson integrator; with gravity it is the
    rigid-body analogue of Störmer–Verlet (Dullweber, Leimkuhler & McLachlan
    1997). Per step: one isotropic turn and three axis rotations (or five axis
    rotations), and two torque evaluations.

    **Arguments** (the same for every solver in this module):

    - `compensated`: add each step's increment to the state with Kahan
        compensated summation (default `True`).
    - `free_body`: the split of the free-body drift, `"symmetric-top"` (default)
        or `"axes"` (module docstring). Measured against Dopri8 (max relative
        energy error along the run; final (R, ω) error):
        - symmetric body: exact; the Earth's 305-day wobble to 3e-15 at h = 1 h
          (`"axes"`: off by 0.12 with Yoshida4, 1.1e-4 at h = 600 s);
        - I = (1, 2, 3), h = 0.1, Yoshida4: energy 1.0e-7 and 6.5e-8 against
          9.4e-7 and 7.9e-7 (a generic start; near the middle axis, t = 1000),
          final 2.2e-5 and 2.2e-5 against 7.3e-5 and 2.4e-4; Verlet: energy
          1.2e-4 and 8.7e-5 against 7.2e-5 and 6.9e-5 (1.3–3.4× larger on every
          free asymmetric body tried), final 1.6e-2 and 5.9e-3 against 1.1e-2
          and 1.5e-2;
        - heavy symmetric top, h = 0.01, Yoshida4: energy 5.5e-11 against
          1.3e-8, final 2.5e-8 against 6.0e-7;
        - time per step (`lj.simulate`, 10⁵ steps): Verlet 5 % more; Yoshida4
          20 % less on a free body (one isotropic turn per step), 4 % with
          gravity; vmapped over 1024 free bodies 28 % and 36 % less.

    ??? cite "References"

        - Touma & Wisdom, Astron. J. 107, 1189 (1994).
        - McLachlan, Phys. Rev. Lett. 71, 3043 (1993).
        - Dullweber, Leimkuhler & McLachlan, J. Chem. Phys. 107, 5840 (1997).
    """

    composition_weights: ClassVar[tuple[float, ...]] = (1.0,)
    nominal_order: ClassVar[int] = 2
    compensated: bool = eqx.field(default=True, static=True)
    free_body: str = eqx.field(default="symmetric-top", static=True)


class RigidBodyYoshida4(AbstractRigidBodySplitting):
    r"""Order-4 Lie–Poisson splitting: Yoshida's triple jump of `RigidBodyVerlet`,

    $$\Phi_h = \Phi_{w_1 h}\,\Phi_{w_0 h}\,\Phi_{w_1 h},\qquad
    w_1 = \frac{1}{2 - 2^{1/3}},\; w_0 = 1 - 2 w_1.$$

    ??? cite "References"

        - Yoshida, Phys. Lett. A 150, 262 (1990).
        - Touma & Wisdom, Astron. J. 107, 1189 (1994).
        - McLachlan, Phys. Rev. Lett. 71, 3043 (1993).
    """

    composition_weights: ClassVar[tuple[float, ...]] = YOSHIDA4_WEIGHTS
    nominal_order: ClassVar[int] = 4
    compensated: bool = eqx.field(default=True, static=True)
    free_body: str = eqx.field(default="symmetric-top", static=True)


class QuaternionProjection(AbstractProjectedSolver):
    r"""Any diffrax solver on a rigid body, with $q \mapsto q/|q|$ after each step.

    The baseline for the Lie–Poisson methods: an adaptive Runge–Kutta method (say
    `diffrax.Tsit5()`) on the `RigidBodyTerm`, whose quaternion would otherwise
    drift off the unit sphere with the local error. The projection changes the
    state by about that error, so the error estimate and an FSAL solver's stored
    derivative stay valid to the same order; `isinstance` checks (adaptive or not)
    are those of the wrapped solver.

    ??? cite "References"

        - Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
          Springer (2006), §IV.4 (projection methods).
    """

    solver: diffrax.AbstractSolver

    def project(self, terms, t1, y1, args):
        del terms, t1, args
        quaternion, body_momentum = y1
        unit = (quaternion / jnp.linalg.norm(quaternion), body_momentum)
        return unit, diffrax.RESULTS.successful
