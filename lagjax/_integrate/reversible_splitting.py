r"""The backward pass of a splitting method, stage by stage: each stage walked back
and pulled back with one linearization.

A splitting step is a product of kicks $K_b: (q, p) \mapsto (q, p + b h F(q))$
and drifts $D_a: (q, p) \mapsto (q + a h\,\partial T/\partial p(p), p)$. Each leaves
the variable it is evaluated at unchanged, so the point a stage's derivative needs
is the point its inverse ($K_{-b}$, $D_{-a}$) is evaluated at. Walking a step back
stage by stage, one `jax.vjp` per stage gives both at once,

$$p \mathrel{-}= b h F(q),\quad \bar q \mathrel{+}= b h\, F'(q)^{\top} \bar p,
\qquad q \mathrel{-}= a h\, T'(p),\quad \bar p \mathrel{+}= a h\, T''(p)^{\top}
\bar q,$$

(and $\bar\theta$ from the same pullbacks): one force and one transposed force per
stage, where stepping back and then pulling back a whole step (`reversible_loop`'s
generic walk) evaluates the force twice. The last kick of step k and the first of
step k + 1 act at the same $q_{k+1}$ (first-same-as-last): one pullback with the
sum of their cotangents, $b_0 h \bar p_{\text{in}} + b_s h (\bar p_{\text{in}} +
\bar p_{\text{saved}})$, where $\bar p_{\text{saved}}$ is the cotangent entering at
a mark between them.

Round-off. The states are walked back as the solver walks forward: stage points
in place, the step's increments summed beside them and added to the state once
with the forward run's Kahan compensation. The cotangents are summed the same way:
a step's increments of $\bar q$, $\bar p$ and $\bar\theta$ (small: O(h) of the
cotangent) meet the running cotangent once per step through a compensated sum, so
the adjoint's own round-off grows like a compensated forward run's, not like a
plain sum's (10⁶ Störmer–Verlet steps on Kepler: `benchmarks/adjoint_round_off.py`).

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.
(2006), §II.5 (splittings), §VIII.5 (round-off, compensated summation); Kahan,
"Further remarks on reducing truncation errors", CACM 8 (1965); Gomez, Ren,
Urtasun & Grosse, "The reversible residual network", NeurIPS 2017.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._integrate.reversible_steps import repeat_steps
from lagjax._integrate.scan_body import steps_per_trip
from lagjax.solvers.compensated import compensated_add
from lagjax.solvers.splitting_engine import AbstractSplittingSolver


class SplittingCotangent(NamedTuple):
    """The cotangents of q, p and the parameters, each a compensated sum (value,
    Kahan compensation)."""

    q: Any
    p: Any
    params: Any
    q_error: Any
    p_error: Any
    params_error: Any

    def plus(self, q: Any, p: Any, params: Any) -> SplittingCotangent:
        """The sums with one more increment each (compensated)."""
        q, q_error = compensated_add(self.q, q, self.q_error)
        p, p_error = compensated_add(self.p, p, self.p_error)
        params, params_error = compensated_add(self.params, params, self.params_error)
        return SplittingCotangent(q, p, params, q_error, p_error, params_error)


def _tree_add(a: Any, b: Any) -> Any:
    return jax.tree_util.tree_map(jnp.add, a, b)


def _tree_sub(a: Any, b: Any) -> Any:
    return jax.tree_util.tree_map(jnp.subtract, a, b)


def _zeros(tree: Any) -> Any:
    return jax.tree_util.tree_map(jnp.zeros_like, tree)


def _scaled(tree: Any, factor: Any) -> Any:
    return jax.tree_util.tree_map(lambda x: factor * x, tree)


def walk_steps_back(step_back, cotangent, y, state, end, length, saved, solver):
    """The cotangent after `length` calls of `step_back(y, state, step, cotangent,
    saved, at_mark) -> (y, state, cotangent)` from step `end` − 1 down, `saved`
    (None: zeros) entering at the lowest step, unrolled as the forward loop is
    (a traced length: not unrolled)."""
    low = end - length
    saved = _zeros(y) if saved is None else saved

    def one_back(carry):
        y, state, k, cotangent = carry
        y, state, cotangent = step_back(y, state, k - 1, cotangent, saved, k - 1 == low)
        return y, state, k - 1, cotangent

    carry = (y, state, jnp.asarray(end), cotangent)
    return repeat_steps(one_back, carry, length, steps_per_trip(solver))[-1]


class SplittingWalk(eqx.Module):
    """The backward pass of one splitting run: `start` at the last mark, `back`
    over the steps between marks, `finish` at y0 (`reversible_loop` drives it)."""

    solver: AbstractSplittingSolver
    static: Any
    clock: Any

    def _pieces(self, params):
        terms, args = eqx.combine(params, self.static)
        return terms, args

    def _force_pullback(self, params, t, q):
        """`(F(t, q), pullback)`, the pullback of (q, params)."""

        def force(q, params):
            (_, term_p), args = self._pieces(params)
            return term_p.vf(t, q, args)

        return jax.vjp(force, q, params)

    def _kick_cotangent(self, params, force, control, p_bar):
        """The force's cotangent from a kick `prod(force, control)` (linear)."""
        (_, term_p), _ = self._pieces(params)
        _, transpose = jax.vjp(lambda f: term_p.prod(f, control), force)
        return transpose(p_bar)[0]

    def _kick(self, params, force, control):
        (_, term_p), _ = self._pieces(params)
        return term_p.prod(force, control)

    def _controls(self, params, step):
        """`(start, stop, control_q, control_p)` of step `step`."""
        (term_q, term_p), _ = self._pieces(params)
        start, stop = self.clock.times(step)
        return start, stop, term_q.contr(start, stop), term_p.contr(start, stop)

    def start(self, cotangent, y, state, params, steps: int) -> SplittingCotangent:
        """The cotangent at the last mark (after `steps` steps), with the last
        kick's pullback at its q (the first-same-as-last force has no next step)."""
        q_bar, p_bar = cotangent
        zero = SplittingCotangent(
            q_bar, p_bar, _zeros(params), _zeros(q_bar), _zeros(p_bar), _zeros(params)
        )
        if steps == 0:
            return zero
        _, stop, _, control_p = self._controls(params, jnp.asarray(steps - 1))
        last = _scaled(control_p, self.solver.kick_coefficients[-1])
        force, pullback = self._force_pullback(params, stop, y[0])
        q_inc, params_inc = pullback(self._kick_cotangent(params, force, last, p_bar))
        return zero.plus(q_inc, _zeros(p_bar), params_inc)

    def back(self, cotangent: Any, y, state, end, length: Any, params,
             saved) -> SplittingCotangent:  # fmt: skip
        """Walk back `length` steps from `(y, state)` after step `end` − 1; the
        cotangent `saved = (q̄, p̄)` of the state reached enters there (None: no
        mark)."""

        def step_back(y, state, step, cotangent, saved, at_mark):
            return self._step_back(y, state, step, cotangent, params, saved, at_mark)

        return walk_steps_back(step_back, cotangent, y, state, end, length,
                               saved, self.solver)  # fmt: skip

    def finish(self, cotangent: Any, params):
        """`(ȳ0, θ̄)`: the first step's pullback already took the initial force's."""
        del params
        return (cotangent.q, cotangent.p), cotangent.params

    def _step_back(self, y, state, step, cotangent, params, saved, at_mark):
        """Step `step` walked back and pulled back: `(y, state, cotangent)` before
        it."""
        solver = self.solver
        kicks, drifts = solver.kick_coefficients, solver.drift_coefficients
        q, p = y
        compensation, force = state
        start, stop, control_q, control_p = self._controls(params, step)
        span = stop - start
        stage_starts = [sum(drifts[:i]) for i in range(len(drifts))]

        dp = self._kick(params, force, _scaled(control_p, kicks[-1]))
        q_now, p_now, delta_q, delta_p = q, _tree_sub(p, dp), None, _scaled(dp, -1.0)
        q_bar, p_bar = cotangent.q, cotangent.p
        q_inc, p_inc, params_inc = _zeros(q), _zeros(p), _zeros(params)
        for i in reversed(range(len(drifts))):
            t_drift = start + (stage_starts[i] + drifts[i] / 2) * span
            drift_control = _scaled(control_q, drifts[i])

            def drift(p, params, t=t_drift, control=drift_control):
                (term_q, _), args = self._pieces(params)
                return term_q.vf_prod(t, p, args, control)

            dq, pullback = jax.vjp(drift, p_now, params)
            p_step, params_step = pullback(q_bar)
            p_bar, p_inc = _tree_add(p_bar, p_step), _tree_add(p_inc, p_step)
            params_inc = _tree_add(params_inc, params_step)
            q_now = _tree_sub(q_now, dq)
            delta_q = _scaled(dq, -1.0) if delta_q is None else _tree_sub(delta_q, dq)
            if i == 0:
                break
            t_kick = start + stage_starts[i] * span
            kick_control = _scaled(control_p, kicks[i])
            force, pullback = self._force_pullback(params, t_kick, q_now)
            dp = self._kick(params, force, kick_control)
            p_now, delta_p = _tree_sub(p_now, dp), _tree_sub(delta_p, dp)
            q_step, params_step = pullback(
                self._kick_cotangent(params, force, kick_control, p_bar)
            )
            q_bar, q_inc = _tree_add(q_bar, q_step), _tree_add(q_inc, q_step)
            params_inc = _tree_add(params_inc, params_step)

        if compensation is None:
            q_before = q_now
        else:
            q_before, compensation_q = compensated_add(q, delta_q, compensation[0])
        force, pullback = self._force_pullback(params, start, q_before)
        first_control = _scaled(control_p, kicks[0])
        dp = self._kick(params, force, first_control)
        if compensation is None:
            p_before = _tree_sub(p_now, dp)
        else:
            p_before, compensation_p = compensated_add(
                p, _tree_sub(delta_p, dp), compensation[1]
            )
            compensation = (compensation_q, compensation_p)

        # One pullback at q_before for two kicks: this step's first, and the last
        # of the step before (none before step 0), which sees the saved state's
        # cotangent too when a mark lies between them.
        saved_q, saved_p = jax.tree_util.tree_map(
            lambda s: jnp.where(at_mark, s, jnp.zeros_like(s)), saved
        )
        *_, previous_control = self._controls(params, jnp.maximum(step - 1, 0))
        previous_last = _scaled(previous_control, kicks[-1] * (step > 0))
        force_bar = _tree_add(
            self._kick_cotangent(params, force, first_control, p_bar),
            self._kick_cotangent(
                params, force, previous_last, _tree_add(p_bar, saved_p)
            ),
        )
        q_step, params_step = pullback(force_bar)
        q_inc = _tree_add(_tree_add(q_inc, q_step), saved_q)
        p_inc = _tree_add(p_inc, saved_p)
        params_inc = _tree_add(params_inc, params_step)
        cotangent = cotangent.plus(q_inc, p_inc, params_inc)
        return (q_before, p_before), (compensation, force), cotangent
