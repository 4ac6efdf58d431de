r"""The engine of the splitting methods: one kick–drift–…–kick step, any table.

Every method of `lagjax.solvers.splitting` is an alternating product of the exact
flows of $T(p)$ and $V(q)$ — the *drift* $q \mapsto q + \tau\,\partial T/\partial p$
and the *kick* $p \mapsto p - \tau\,\partial V/\partial q$ — and differs from the
others only in its coefficient tables; `AbstractSplittingSolver` runs any table.

The final kick of a step is evaluated at the new state and reused as the first
kick of the next step (first-same-as-last, kept in the solver state), so a step
costs exactly one force evaluation per drift. diffrax signals a changed state
or vector field between steps with `made_jump`, which triggers re-evaluation.

Within a step the updates are accumulated as small increments Δq, Δp and added
to the state once, with Kahan's compensated summation
(`lagjax.solvers.compensated`); with `compensated=False` the state is updated in
place, stage by stage, exactly as a hand-written loop does. The stage positions and momenta at which the
forces and velocities are evaluated are advanced in place, as a hand-written loop
does (one add per drift or kick on the path from one force to the next); the
increments are summed alongside, off that path. Both round to the state's last
bit at every stage, so the error behaviour is that of evaluating at q0 + Δq, and
a composition with s stages runs at a hand-written loop's speed per stage
(`benchmarks/solver_overhead.py`). The round-off committed per step is then of the
size of the increment's last bit instead of the state's, so over n steps it
random-walks (Brouwer's law, ∝ √n) from a level about 1/h times lower and
cannot build up into a drift of the invariants.

Term convention (as `diffrax.SemiImplicitEuler`): `terms = (term_q, term_p)` and
`y = (q, p)`; `term_q` is the drift, a function of `p`, and `term_p` the kick, a
function of `q`.
"""

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar

import jax
import jax.lax as lax
from diffrax import (
    RESULTS,
    AbstractSolver,
    AbstractTerm,
    LocalLinearInterpolation,
)

from lagjax._core.solver_kinds import AbstractSplittingMethod, AbstractTimeReversible
from lagjax.solvers.compensated import compensated_add, zero_compensation

if TYPE_CHECKING:
    from typing import ClassVar as AbstractClassVar
    from typing import ClassVar as AbstractVar
else:
    from equinox import AbstractClassVar, AbstractVar

# (compensation for y or None, kick vector field at the current (t, q)).
_SplittingState = tuple[Any, Any]


def _scaled(control: Any, coefficient: float) -> Any:
    return jax.tree_util.tree_map(lambda c: coefficient * c, control)


def _add(x: Any, y: Any) -> Any:
    return jax.tree_util.tree_map(lambda a, b: a + b, x, y)


def _palindrome(table: tuple[float, ...]) -> bool:
    return all(abs(a - b) <= 1e-15 for a, b in zip(table, reversed(table)))


class AbstractSplittingSolver(
    AbstractSplittingMethod, AbstractTimeReversible, AbstractSolver[_SplittingState]
):
    r"""A kick–drift–…–kick splitting method for $H = T(p) + V(q)$.

    Subclasses set `kick_coefficients` $b_0..b_s$ and `drift_coefficients`
    $a_1..a_s$ (each summing to one) and the nominal order; this class runs

    $$p \mathrel{+}= b_0 h F(q);\quad \text{for } i = 1..s:\;
    q \mathrel{+}= a_i h\, \partial T/\partial p(p),\;
    p \mathrel{+}= b_i h F(q),$$

    with $F = -\partial V/\partial q$. A kick sees the time reached by the drifts
    before it ($t_0 + h\sum_{j \le i} a_j$), which keeps the order for a
    time-dependent $V(q, t)$; a drift sees the midpoint of its own sub-interval.
    Fixed step only: no error estimate is made.

    ??? cite "References"

        - McLachlan & Quispel, *Splitting methods*, Acta Numerica 11, 341 (2002).
        - Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
          Springer (2006), §II.5 and §V.3.
    """

    kick_coefficients: AbstractClassVar[tuple[float, ...]]
    drift_coefficients: AbstractClassVar[tuple[float, ...]]
    nominal_order: AbstractClassVar[int]
    compensated: AbstractVar[bool]
    term_structure: ClassVar = (AbstractTerm, AbstractTerm)
    interpolation_cls: ClassVar[Callable[..., LocalLinearInterpolation]] = (
        LocalLinearInterpolation
    )

    def __check_init__(self):
        kicks, drifts = self.kick_coefficients, self.drift_coefficients
        if len(kicks) != len(drifts) + 1:
            raise ValueError("a splitting table needs one more kick than drifts")
        for name, table in (("kick", kicks), ("drift", drifts)):
            if abs(sum(table) - 1) > 1e-13:
                raise ValueError(f"{name} coefficients sum to {sum(table)}, not 1")

    def order(self, terms: Any) -> int:
        return self.nominal_order

    def is_time_reversible(self) -> bool:
        """Symmetric when both coefficient tables are palindromes (HLW §V.3)."""
        return all(
            _palindrome(table)
            for table in (self.kick_coefficients, self.drift_coefficients)
        )

    def init(self, terms, t0, t1, y0, args) -> _SplittingState:
        _, term_p = terms
        q0, _ = y0
        compensation = zero_compensation(y0) if self.compensated else None
        return compensation, term_p.vf(t0, q0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        _, term_p = terms
        q0, p0 = y0
        compensation, force = solver_state
        if made_jump is not False:
            # After a jump the stored force belongs to the old vector field.
            force = lax.cond(made_jump, lambda: term_p.vf(t0, q0, args), lambda: force)
        stage, increments = self._all_but_last_kick(terms, t0, t1, y0, args, force)
        last_kick = _scaled(term_p.contr(t0, t1), self.kick_coefficients[-1])
        # The last kick is evaluated at the new position, so it doubles as the
        # first kick of the next step (first-same-as-last).
        if compensation is None:
            # The stage point is the new state, updated in place as a hand-written
            # loop does (the same arithmetic). Adding summed increments instead
            # would keep each force alive to the end of the step, and XLA
            # recomputes such a value in every fused kernel that reads it (a
            # division per force: 1.4x a hand-written loop under vmap).
            q1, p_before_last_kick = stage
            force = term_p.vf(t1, q1, args)
            p1 = _add(p_before_last_kick, term_p.prod(force, last_kick))
        else:
            # The increments stay small, so they keep their low-order bits; they
            # meet the (large) state once per step, through the compensated sum.
            (delta_q, delta_p), (compensation_q, compensation_p) = (
                increments,
                compensation,
            )
            q1, compensation_q = compensated_add(q0, delta_q, compensation_q)
            force = term_p.vf(t1, q1, args)
            delta_p = _add(delta_p, term_p.prod(force, last_kick))
            p1, compensation_p = compensated_add(p0, delta_p, compensation_p)
            compensation = (compensation_q, compensation_p)
        y1 = (q1, p1)
        dense_info = dict(y0=y0, y1=y1)
        return y1, None, dense_info, (compensation, force), RESULTS.successful

    def _all_but_last_kick(
        self, terms, t0, t1, y0, args, force
    ) -> tuple[tuple[Any, Any], tuple[Any, Any]]:
        """`((q, p), (Δq, Δp))` after every drift and every kick but the last: the
        stage point reached and the increments summed on the way.

        `force` is the kick vector field at (t0, q0).
        """
        term_q, term_p = terms
        q0, p0 = y0
        control_q, control_p = term_q.contr(t0, t1), term_p.contr(t0, t1)
        kicks, drifts = self.kick_coefficients, self.drift_coefficients
        delta_p = term_p.prod(force, _scaled(control_p, kicks[0]))
        # The stage point (q_now, p_now) moves in place, the increments are summed
        # beside it: the path from one force evaluation to the next is then two
        # adds, not four (each stage point is rounded to the state's last bit
        # either way).
        q_now, p_now, delta_q = q0, _add(p0, delta_p), None
        drift_clock = 0.0  # fraction of the step the drifts have covered so far
        for index, drift in enumerate(drifts):
            t_drift = t0 + (drift_clock + drift / 2) * (t1 - t0)
            dq = term_q.vf_prod(t_drift, p_now, args, _scaled(control_q, drift))
            delta_q = dq if delta_q is None else _add(delta_q, dq)
            q_now = _add(q_now, dq)
            drift_clock += drift
            if index + 1 < len(drifts):
                t_kick = t0 + drift_clock * (t1 - t0)
                force = term_p.vf(t_kick, q_now, args)
                dp = term_p.prod(force, _scaled(control_p, kicks[index + 1]))
                delta_p = _add(delta_p, dp)
                p_now = _add(p_now, dp)
        return (q_now, p_now), (delta_q, delta_p)

    def func(self, terms, t0, y0, args):
        term_q, term_p = terms
        q0, p0 = y0
        return term_q.vf(t0, p0, args), term_p.vf(t0, q0, args)
