r"""Explicit symplectic splitting and composition methods for separable Hamiltonians.

For $H(q, p) = T(p) + V(q)$ the flows of the two halves are exact and explicit:
the *drift* $q \mapsto q + \tau\,\partial T/\partial p$ and the *kick*
$p \mapsto p - \tau\,\partial V/\partial q$. Every method here is one alternating
product of them,

$$\Phi_h = K_{b_s h} \circ D_{a_s h} \circ K_{b_{s-1} h} \circ \cdots \circ
D_{a_1 h} \circ K_{b_0 h},$$

which is symplectic because each factor is, and time-reversible when the
coefficient sequences are palindromes. The methods differ only in their
coefficient tables (`lagjax.solvers.splitting_tables`), so one engine
(`AbstractSplittingSolver`, `lagjax.solvers.splitting_engine`) runs them all:

- Symmetric *compositions* of Störmer–Verlet with weights $\gamma_1..\gamma_m$
  (Yoshida, Kahan–Li, Sofroniou–Spaletta) become $a = \gamma$,
  $b = (\gamma_1/2, (\gamma_1+\gamma_2)/2, \ldots, \gamma_m/2)$: adjacent
  half-kicks merge, so a step costs $m$ force evaluations, not $2m$.
- The final kick of a step is evaluated at the new state and reused as the first
  kick of the next step (first-same-as-last), so a step costs exactly one force
  evaluation per drift; the engine's module says how a step is run, and how its
  increments reach the state (Kahan's compensated summation, `compensated=True`).

Term convention (as `diffrax.SemiImplicitEuler`): `terms = (term_q, term_p)` and
`y = (q, p)`; `term_q` is the drift, a function of `p`, and `term_p` the kick, a
function of `q`.
"""

from typing import ClassVar

import equinox as eqx

from lagjax.solvers.splitting_engine import (
    AbstractSplittingSolver as AbstractSplittingSolver,  # tests import it from here
)
from lagjax.solvers.splitting_tables import (
    BLANES_MOAN4_DRIFTS,
    BLANES_MOAN4_KICKS,
    BLANES_MOAN6_DRIFTS,
    BLANES_MOAN6_KICKS,
    BLANES_MOAN_NYSTROM6_DRIFTS,
    BLANES_MOAN_NYSTROM6_KICKS,
    KAHAN_LI8_WEIGHTS,
    SOFSPA10_WEIGHTS,
    VERLET_WEIGHTS,
    YOSHIDA4_WEIGHTS,
    YOSHIDA6_WEIGHTS,
    merged_kicks,
)

_Coefficients = ClassVar[tuple[float, ...]]


class StormerVerlet(AbstractSplittingSolver):
    r"""Störmer–Verlet (velocity Verlet, leapfrog), order 2.

    $$p_{1/2} = p_0 + \tfrac{h}{2} F(q_0),\quad
    q_1 = q_0 + h\,\partial T/\partial p(p_{1/2}),\quad
    p_1 = p_{1/2} + \tfrac{h}{2} F(q_1).$$

    One force evaluation per step (the last kick is reused by the next step).

    **Arguments** (the same for every solver in this module):

    - `compensated`: add each step's increment to the state with Kahan
        compensated summation (default `True`); `False` adds it plainly.

    ??? cite "References"

        - Verlet, *Computer "experiments" on classical fluids*, Phys. Rev. 159,
          98 (1967).
        - Hairer, Lubich & Wanner, *Geometric numerical integration illustrated
          by the Störmer–Verlet method*, Acta Numerica 12, 399 (2003).
    """

    kick_coefficients: _Coefficients = merged_kicks(VERLET_WEIGHTS)
    drift_coefficients: _Coefficients = VERLET_WEIGHTS
    nominal_order: ClassVar[int] = 2
    compensated: bool = eqx.field(default=True, static=True)


class Yoshida4(AbstractSplittingSolver):
    r"""Yoshida's fourth-order triple jump: three Störmer–Verlet steps.

    $$\Phi_h = \Phi^{SV}_{w_1 h} \circ \Phi^{SV}_{w_0 h} \circ \Phi^{SV}_{w_1 h},
    \qquad w_1 = \frac{1}{2 - 2^{1/3}},\; w_0 = 1 - 2 w_1.$$

    Three force evaluations per step.

    ??? cite "References"

        - Yoshida, *Construction of higher order symplectic integrators*,
          Phys. Lett. A 150, 262 (1990).
        - Forest & Ruth, *Fourth-order symplectic integration*, Physica D 43,
          105 (1990).
    """

    kick_coefficients: _Coefficients = merged_kicks(YOSHIDA4_WEIGHTS)
    drift_coefficients: _Coefficients = YOSHIDA4_WEIGHTS
    nominal_order: ClassVar[int] = 4
    compensated: bool = eqx.field(default=True, static=True)


class Yoshida6(AbstractSplittingSolver):
    r"""Yoshida's sixth-order composition, solution A: seven Störmer–Verlet steps.

    $$\Phi_h = \Phi^{SV}_{w_3 h} \circ \Phi^{SV}_{w_2 h} \circ \Phi^{SV}_{w_1 h}
    \circ \Phi^{SV}_{w_0 h} \circ \Phi^{SV}_{w_1 h} \circ \Phi^{SV}_{w_2 h}
    \circ \Phi^{SV}_{w_3 h}.$$

    Seven force evaluations per step.

    ??? cite "References"

        - Yoshida, *Construction of higher order symplectic integrators*,
          Phys. Lett. A 150, 262 (1990), Table 1, solution A.
    """

    kick_coefficients: _Coefficients = merged_kicks(YOSHIDA6_WEIGHTS)
    drift_coefficients: _Coefficients = YOSHIDA6_WEIGHTS
    nominal_order: ClassVar[int] = 6
    compensated: bool = eqx.field(default=True, static=True)


class KahanLi8(AbstractSplittingSolver):
    r"""Kahan and Li's eighth-order symmetric composition s17odr8a.

    $$\Phi_h = \Phi^{SV}_{\gamma_{17} h} \circ \cdots \circ
    \Phi^{SV}_{\gamma_1 h},\qquad \gamma_{18-i} = \gamma_i,$$

    with weights optimised for small error constants. 17 force evaluations per
    step.

    ??? cite "References"

        - Kahan & Li, *Composition constants for raising the orders of
          unconventional schemes for ordinary differential equations*,
          Math. Comp. 66, 1089 (1997).
        - Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
          Springer (2006), §V.3.2.
    """

    kick_coefficients: _Coefficients = merged_kicks(KAHAN_LI8_WEIGHTS)
    drift_coefficients: _Coefficients = KAHAN_LI8_WEIGHTS
    nominal_order: ClassVar[int] = 8
    compensated: bool = eqx.field(default=True, static=True)


class SofSpa10(AbstractSplittingSolver):
    r"""Sofroniou and Spaletta's tenth-order symmetric composition s35odr10.

    $$\Phi_h = \Phi^{SV}_{\gamma_{35} h} \circ \cdots \circ
    \Phi^{SV}_{\gamma_1 h},\qquad \gamma_{36-i} = \gamma_i.$$

    35 force evaluations per step; worth it when very high accuracy is wanted.

    ??? cite "References"

        - Sofroniou & Spaletta, *Derivation of symmetric composition constants
          for symmetric integrators*, Optim. Methods Softw. 20, 597 (2005).
        - Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
          Springer (2006), §V.3.2.
    """

    kick_coefficients: _Coefficients = merged_kicks(SOFSPA10_WEIGHTS)
    drift_coefficients: _Coefficients = SOFSPA10_WEIGHTS
    nominal_order: ClassVar[int] = 10
    compensated: bool = eqx.field(default=True, static=True)


class BlanesMoan4(AbstractSplittingSolver):
    r"""Blanes and Moan's optimised fourth-order splitting S6 (PRK, 6 stages).

    $$\Phi_h = K_{a_1 h} D_{b_1 h} K_{a_2 h} D_{b_2 h} K_{a_3 h} D_{b_3 h}
    K_{a_4 h} D_{b_3 h} K_{a_3 h} D_{b_2 h} K_{a_2 h} D_{b_1 h} K_{a_1 h}.$$

    Not a composition of Verlet steps: the free coefficients minimise the
    leading error terms, giving errors an order of magnitude or more below
    `Yoshida4` at equal cost. Six force evaluations per step.

    ??? cite "References"

        - Blanes & Moan, *Practical symplectic partitioned Runge–Kutta and
          Runge–Kutta–Nyström methods*, J. Comput. Appl. Math. 142, 313
          (2002), method S6.
    """

    kick_coefficients: _Coefficients = BLANES_MOAN4_KICKS
    drift_coefficients: _Coefficients = BLANES_MOAN4_DRIFTS
    nominal_order: ClassVar[int] = 4
    compensated: bool = eqx.field(default=True, static=True)


class BlanesMoan6(AbstractSplittingSolver):
    r"""Blanes and Moan's optimised sixth-order splitting S10 (PRK, 10 stages).

    $$\Phi_h = K_{a_1 h} D_{b_1 h} K_{a_2 h} \cdots D_{b_5 h} K_{a_6 h}
    D_{b_5 h} \cdots K_{a_2 h} D_{b_1 h} K_{a_1 h}.$$

    Like `BlanesMoan4`, not a composition of Verlet steps: its free coefficients
    minimise the leading error terms. The cheapest method here for energy errors
    of 1e-8…1e-11 on an eccentric Kepler orbit (`benchmarks/kepler_saved.py`). Ten
    force evaluations per step.

    ??? cite "References"

        - Blanes & Moan, *Practical symplectic partitioned Runge–Kutta and
          Runge–Kutta–Nyström methods*, J. Comput. Appl. Math. 142, 313
          (2002), Table 2, method S10.
    """

    kick_coefficients: _Coefficients = BLANES_MOAN6_KICKS
    drift_coefficients: _Coefficients = BLANES_MOAN6_DRIFTS
    nominal_order: ClassVar[int] = 6
    compensated: bool = eqx.field(default=True, static=True)


class BlanesMoanNystrom6(AbstractSplittingSolver):
    r"""Blanes and Moan's sixth-order Runge–Kutta–Nyström splitting SRKN$_{11}^b$.

    $$\Phi_h = K_{b_1 h} D_{a_1 h} K_{b_2 h} \cdots K_{b_6 h} D_{a_6 h}
    K_{b_6 h} \cdots D_{a_1 h} K_{b_1 h}.$$

    For kinetic energies quadratic in the momenta (T = ½pᵀM⁻¹p, the usual case)
    the bracket $\{V, \{V, \{V, T\}\}\}$ vanishes, which removes order
    conditions: with that freedom the coefficients are chosen for a much smaller
    error than the general `BlanesMoan6`. On the eccentric Kepler orbit of
    `benchmarks/kepler_saved.py` it is the cheapest method here for energy errors
    near 1e-10. Eleven force evaluations per step. Only for a
    `SeparableHamiltonian` with `quadratic_in_momentum=True` (its default); a
    non-quadratic T (relativistic) would lose the order silently, so it is refused.

    ??? cite "References"

        - Blanes & Moan, *Practical symplectic partitioned Runge–Kutta and
          Runge–Kutta–Nyström methods*, J. Comput. Appl. Math. 142, 313
          (2002), Table 3, method SRKN$_{11}^b$.
    """

    kick_coefficients: _Coefficients = BLANES_MOAN_NYSTROM6_KICKS
    drift_coefficients: _Coefficients = BLANES_MOAN_NYSTROM6_DRIFTS
    nominal_order: ClassVar[int] = 6
    needs_quadratic_kinetic: ClassVar[bool] = True
    compensated: bool = eqx.field(default=True, static=True)
