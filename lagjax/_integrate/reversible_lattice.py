r"""The backward pass of a bit-reversible splitting (`lagjax.BitReversible`),
stage by stage on its integer lattice.

The walk of `reversible_splitting` with the lattice's arithmetic: each stage is
undone in integers — $P \mathrel{-}= [b h F(\varepsilon_q Q)/\varepsilon_p]$,
$Q \mathrel{-}= [a h\, T'(\varepsilon_p P)/\varepsilon_q]$ — which returns the
forward run's stage points bit for bit, and the vector field evaluated for the
undo is linearized at the same point, so one `jax.vjp` per stage gives both the
step back and the pullback,

$$\bar q \mathrel{+}= b h\, F'(q)^{\top} \bar p, \qquad
\bar p \mathrel{+}= a h\, T''(p)^{\top} \bar q,$$

the derivative the forward run's tangent rule takes (the rounding passed
straight through). The first-same-as-last force is pulled back once for the last
kick of one step and the first of the next, as there. The cotangents are summed
with Kahan compensation (`SplittingCotangent`): the states are exact, so the
gradient's only round-off is the cotangents' own.

References: Rein & Tamayo, "JANUS: a bit-wise reversible integrator for N-body
dynamics", MNRAS 473, 3351 (2018); Gomez, Ren, Urtasun & Grosse, "The reversible
residual network", NeurIPS 2017.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from lagjax._integrate.reversible_splitting import (
    SplittingCotangent,
    walk_steps_back,
)
from lagjax.solvers.bit_reversible import BitReversible, step_size
from lagjax.solvers.integer_lattice import lattice_moved


def _tree_add(a: Any, b: Any) -> Any:
    return jax.tree_util.tree_map(jnp.add, a, b)


def _zeros(tree: Any) -> Any:
    return jax.tree_util.tree_map(jnp.zeros_like, tree)


class LatticeWalk(eqx.Module):
    """The backward pass of one `BitReversible` run: `start` at the last mark,
    `back` over the steps between marks, `finish` at y0 (`reversible_loop`
    drives it)."""

    solver: BitReversible
    static: Any
    clock: Any

    def _field_pullback(self, params, which: int, t, x):
        """`(vf(t, x), pullback of (x, params))` of the drift (0) or kick (1) term."""

        def field(x, params):
            terms, args = eqx.combine(params, self.static)
            return terms[which].vf(t, x, args)

        return jax.vjp(field, x, params)

    def _prod_cotangent(self, params, which: int, value, control, bar):
        """The vector field's cotangent from `prod(value, control)` (linear)."""
        terms, _ = eqx.combine(params, self.static)
        _, transpose = jax.vjp(lambda f: terms[which].prod(f, control), value)
        return transpose(bar)[0]

    def _step(self, step, nominal):
        """`(start, stop, h)` of step `step` as the forward run took it."""
        start, stop = self.clock.times(step)
        return start, stop, step_size(start, stop, nominal)

    def start(self, cotangent, y, state, params, steps: int) -> SplittingCotangent:
        """The cotangent at the last mark, with the last kick's pullback at its q
        (the first-same-as-last force has no next step)."""
        q_bar, p_bar = cotangent
        zero = SplittingCotangent(
            q_bar, p_bar, _zeros(params), _zeros(q_bar), _zeros(p_bar), _zeros(params)
        )
        if steps == 0:
            return zero
        _, stop, h = self._step(jnp.asarray(steps - 1), state[3])
        last = self.solver.method.kick_coefficients[-1] * h
        force, pullback = self._field_pullback(params, 1, stop, y[0])
        q_inc, params_inc = pullback(
            self._prod_cotangent(params, 1, force, last, p_bar)
        )
        return zero.plus(q_inc, _zeros(p_bar), params_inc)

    def back(self, cotangent: Any, y, state, end, length: Any, params,
             saved) -> SplittingCotangent:  # fmt: skip
        """Walk back `length` steps from `(y, state)` after step `end` − 1; the
        cotangent `saved = (q̄, p̄)` of the state reached enters there (None: no
        mark)."""

        def step_back(y, state, step, cotangent, saved, at_mark):
            del y  # the lattice state holds it, exactly
            return self._step_back(state, step, cotangent, params, saved, at_mark)

        return walk_steps_back(step_back, cotangent, y, state, end, length,
                               saved, self.solver)  # fmt: skip

    def finish(self, cotangent: Any, params):
        """`(ȳ0, θ̄)`: the first step's pullback already took the initial force's."""
        del params
        return (cotangent.q, cotangent.p), cotangent.params

    def _step_back(self, state, step, cotangent, params, saved, at_mark):
        """Step `step` undone on the lattice and pulled back: `(y, state,
        cotangent)` before it."""
        method = self.solver.method
        kicks, drifts = method.kick_coefficients, method.drift_coefficients
        lattice, (q_units, p_units), force, nominal = state
        start, stop, h = self._step(step, nominal)
        stage_starts = [sum(drifts[:i]) for i in range(len(drifts))]

        def unkick(p_units, force, coefficient):
            kick = jax.tree_util.tree_map(
                jnp.negative,
                eqx.combine(params, self.static)[0][1].prod(force, coefficient * h),
            )
            return lattice_moved(p_units, kick, lattice.p)[0]

        p_units = unkick(p_units, force, kicks[-1])
        q_bar, p_bar = cotangent.q, cotangent.p
        q_inc, p_inc = _zeros(q_bar), _zeros(p_bar)
        params_inc = _zeros(params)
        for i in reversed(range(len(drifts))):
            t_drift = start + (stage_starts[i] + drifts[i] / 2) * (stop - start)
            p_now = lattice.decode_p(p_units)
            velocity, pullback = self._field_pullback(params, 0, t_drift, p_now)
            control = drifts[i] * h
            p_step, params_step = pullback(
                self._prod_cotangent(params, 0, velocity, control, q_bar)
            )
            p_bar, p_inc = _tree_add(p_bar, p_step), _tree_add(p_inc, p_step)
            params_inc = _tree_add(params_inc, params_step)
            terms, _ = eqx.combine(params, self.static)
            back = jax.tree_util.tree_map(
                jnp.negative, terms[0].prod(velocity, control)
            )
            q_units = lattice_moved(q_units, back, lattice.q)[0]
            if i == 0:
                break
            t_kick = start + stage_starts[i] * (stop - start)
            q_now = lattice.decode_q(q_units)
            force, pullback = self._field_pullback(params, 1, t_kick, q_now)
            p_units = unkick(p_units, force, kicks[i])
            q_step, params_step = pullback(
                self._prod_cotangent(params, 1, force, kicks[i] * h, p_bar)
            )
            q_bar, q_inc = _tree_add(q_bar, q_step), _tree_add(q_inc, q_step)
            params_inc = _tree_add(params_inc, params_step)

        q_before = lattice.decode_q(q_units)
        force, pullback = self._field_pullback(params, 1, start, q_before)
        p_units = unkick(p_units, force, kicks[0])
        # One pullback at q_before for two kicks: this step's first, and the last
        # of the step before (none before step 0), which sees the saved state's
        # cotangent too when a mark lies between them.
        saved_q, saved_p = jax.tree_util.tree_map(
            lambda s: jnp.where(at_mark, s, jnp.zeros_like(s)), saved
        )
        _, _, previous_h = self._step(jnp.maximum(step - 1, 0), nominal)
        previous_last = kicks[-1] * previous_h * (step > 0)
        force_bar = _tree_add(
            self._prod_cotangent(params, 1, force, kicks[0] * h, p_bar),
            self._prod_cotangent(
                params, 1, force, previous_last, _tree_add(p_bar, saved_p)
            ),
        )
        q_step, params_step = pullback(force_bar)
        q_inc = _tree_add(_tree_add(q_inc, q_step), saved_q)
        p_inc = _tree_add(p_inc, saved_p)
        params_inc = _tree_add(params_inc, params_step)
        cotangent = cotangent.plus(q_inc, p_inc, params_inc)
        y = (q_before, lattice.decode_p(p_units))
        return y, (lattice, (q_units, p_units), force, nominal), cotangent
