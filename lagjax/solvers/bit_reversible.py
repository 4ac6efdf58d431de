r"""Bit-reversible splitting: q and p on an integer lattice, so that a step of −h
undoes a step of h to the last bit.

Floating-point addition is not invertible — $(x + d) - d \ne x$ in general — so a
symmetric method walked back by steps of −h (the reversible adjoint,
`lagjax.ReversibleAdjoint`) strays from its forward run by the round-off of the
steps between, and very long runs need checkpoints. Integer addition is
invertible. Levesque & Verlet (1993) and Rein & Tamayo (JANUS, 2018) keep the
state as integers $Q = q/\varepsilon_q$, $P = p/\varepsilon_p$ on a fixed-point
lattice and round each stage's increment to it:

$$P \mathrel{+}= \Big[\frac{b_i h\, F(\varepsilon_q Q)}{\varepsilon_p}\Big],
\qquad Q \mathrel{+}= \Big[\frac{a_i h\, \partial T/\partial p(\varepsilon_p P)}
{\varepsilon_q}\Big],$$

with $[\cdot]$ rounding to the nearest integer (halves to even, so $[-x] = -[x]$).
Each stage changes one variable by an amount computed from the other, so its
inverse is the same stage with $-h$, exactly; a palindromic table then makes
$\Phi_{-h} = \Phi_h^{-1}$ bit for bit. The reversible adjoint walks the run back
without a checkpoint and without error, and its gradient equals reverse mode
through the stored run (the same states, the same linearizations).

The derivative is the splitting's own: the rounding is a perturbation of the
size of one lattice unit, and differentiating it (zero almost everywhere) would
be meaningless, so a step's tangent is that of the floating-point step (the
wrapped method, uncompensated) at the lattice state — a straight-through
derivative, the same in forward and reverse mode.

The lattice (`lagjax.solvers.integer_lattice`). Per leaf of q and of p,
$\varepsilon = 2^{k - 62}$ with $2^k$ the first power of two at or above the leaf's
range: `q_range` / `p_range` when given, otherwise `headroom` (1024) times the
largest magnitude of the leaf in y0 (1 for a zero leaf). A state of magnitude $|x|$
then carries about $62 - \log_2(\text{range}/|x|)$ bits, against float64's 53: at
the initial magnitude with the default headroom, 52 — float64 round-off, fixed
instead of floating. A state that leaves its range (or an increment of more than 2⁶¹
units) is poisoned (NaN) and stops the run as a non-finite state; pass them
explicitly when the run will wander far from its start (an orbit released from
apocentre gains (1+e)/(1−e) in momentum).

Exactness needs the increments computed alike forward and backward, which holds
for an autonomous H (a time-dependent V sees its kicks' times rounded
differently: then within a lattice unit per stage).

References: Levesque & Verlet, "Molecular dynamics and time reversibility",
J. Stat. Phys. 72, 519 (1993); Rein & Tamayo, "JANUS: a bit-wise reversible
integrator for N-body dynamics", MNRAS 473, 3351 (2018); Hairer, Lubich & Wanner,
*Geometric Numerical Integration*, 2nd ed. (2006), §V.1.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from diffrax import (
    RESULTS,
    AbstractSolver,
    AbstractTerm,
    LocalLinearInterpolation,
)

from lagjax._core.solver_kinds import AbstractSplittingMethod, AbstractTimeReversible
from lagjax.solvers.integer_lattice import (
    Lattice,
    lattice_moved,
    lattice_spacing,
    off_lattice,
)
from lagjax.solvers.splitting_engine import AbstractSplittingSolver

# Steps within this relative difference of the nominal one are taken as it.
_SAME_STEP = 1e-9


def step_size(t0, t1, nominal):
    """t1 − t0, as ±`nominal` when it is that step up to the times' round-off.

    The loops compute a step's times as t0 + k·dt, which XLA may round
    differently in the forward run and in the walk back (contracted into a
    fused multiply-add in one, not the other): t1 − t0 then differs in its last
    bits, and so would every increment. The nominal step, fixed at `init` and
    carried in the state, is the same bits in both (its sign flipped going back),
    so a step back undoes a step exactly; a step of another length (a shortened
    last step) keeps its own.
    """
    raw = t1 - t0
    same = jnp.abs(jnp.abs(raw) - nominal) <= _SAME_STEP * nominal
    return jnp.where(same, jnp.where(raw < 0, -nominal, nominal), raw)


def _with_tangent(function, point, params, point_dot, params_dot):
    """`(function(point, params), its tangent)`; the tangent None when no tangent
    is carried (the primal run)."""
    if point_dot is None:
        return function(point, params), None
    return jax.jvp(function, (point, params), (point_dot, params_dot))


def _add(a: Any, b: Any) -> Any:
    return jax.tree_util.tree_map(jnp.add, a, b)


def _lattice_step(method, params, static, times, units, lattice: Lattice, force,
                  tangents=None):  # fmt: skip
    """One step of `method`'s table on the lattice: `(units, force, overflow,
    tangents)`.

    `force` is the kick vector field at (t0, q0); the one returned is at (t1, q1)
    (first-same-as-last, as the floating-point engine keeps it). `times =
    (t0, t1, nominal)`; the controls are the step size itself (ODE terms in t).
    With `tangents = (q̇, ṗ, ḟorce, θ̇)` the step's tangent is carried along: each
    stage linearized at the lattice point it is evaluated at, the rounding passed
    straight through; `(q̇1, ṗ1, ḟorce1)` is returned."""
    t0, t1, nominal = times
    (term_q, term_p), _ = eqx.combine(params, static)
    q_units, p_units = units
    q_dot, p_dot, force_dot, params_dot = tangents or (None,) * 4
    h = step_size(t0, t1, nominal)
    kicks, drifts = method.kick_coefficients, method.drift_coefficients

    def velocity(p, params, t):
        (term_q, _), args = eqx.combine(params, static)
        return term_q.vf(t, p, args)

    def field(q, params, t):
        (_, term_p), args = eqx.combine(params, static)
        return term_p.vf(t, q, args)

    def kicked(p_units, p_dot, force, force_dot, coefficient):
        kick = term_p.prod(force, coefficient * h)
        p_units, flag = lattice_moved(p_units, kick, lattice.p)
        if p_dot is not None:
            p_dot = _add(p_dot, term_p.prod(force_dot, coefficient * h))
        return p_units, p_dot, flag

    p_units, p_dot, flag = kicked(p_units, p_dot, force, force_dot, kicks[0])
    q_flags, p_flags = [], [flag]
    clock = 0.0  # fraction of the step the drifts have covered so far
    for index, drift in enumerate(drifts):
        t_drift = t0 + (clock + drift / 2) * (t1 - t0)
        p_now = lattice.decode_p(p_units)
        v, v_dot = _with_tangent(
            lambda p, th, t=t_drift: velocity(p, th, t), p_now, params, p_dot,
            params_dot,
        )  # fmt: skip
        q_units, flag = lattice_moved(q_units, term_q.prod(v, drift * h), lattice.q)
        if q_dot is not None:
            q_dot = _add(q_dot, term_q.prod(v_dot, drift * h))
        clock += drift
        last = index + 1 == len(drifts)
        t_kick = t1 if last else t0 + clock * (t1 - t0)
        q_now = lattice.decode_q(q_units)
        force, force_dot = _with_tangent(
            lambda q, th, t=t_kick: field(q, th, t), q_now, params, q_dot, params_dot
        )
        p_units, p_dot, flag_p = kicked(
            p_units, p_dot, force, force_dot, kicks[index + 1]
        )
        q_flags.append(flag)
        p_flags.append(flag_p)
    units = (q_units, p_units)
    off = (off_lattice(q_units, q_flags), off_lattice(p_units, p_flags))
    return units, force, off, (q_dot, p_dot, force_dot)


@eqx.filter_custom_jvp
def _straight_through_step(y0, force, params, times, units, lattice, *, method,
                           static):  # fmt: skip
    """`(y1, force1, units1, overflow)`: the lattice step's values; its tangent is
    the table's, stage by stage at the lattice points (`_lattice_step`), the
    rounding passed straight through."""
    del y0
    units, force, overflow, _ = _lattice_step(
        method, params, static, times, units, lattice, force
    )
    y1 = (lattice.decode_q(units[0]), lattice.decode_p(units[1]))
    return y1, force, units, overflow


def _zeros_for(tree: Any, dot: Any) -> Any:
    """`dot` with zeros where it has a symbolic zero (None) for an array."""
    return jax.tree_util.tree_map(
        lambda x, t: t if x is None or t is not None else jnp.zeros_like(x),
        tree,
        dot,
        is_leaf=lambda t: t is None,
    )


@_straight_through_step.def_jvp
def _straight_through_tangent(primals, tangents, *, method, static):
    # The times carry no tangent: a fixed step's count is fixed.
    _, force, params, times, units, lattice = primals
    y0_dot, force_dot, params_dot = (
        _zeros_for(x, dot) for x, dot in zip(primals[:3], tangents[:3])
    )
    units, force, overflow, (q_dot, p_dot, force_dot) = _lattice_step(
        method, params, static, times, units, lattice, force,
        (*y0_dot, force_dot, params_dot),
    )  # fmt: skip
    y1 = (lattice.decode_q(units[0]), lattice.decode_p(units[1]))
    no_tangent = jax.tree_util.tree_map(lambda _: None, (units, overflow))
    return (y1, force, units, overflow), ((q_dot, p_dot), force_dot, *no_tangent)


# (lattice spacings, (Q, P) in lattice units, kick vector field at the current q,
# the nominal step |t1 − t0| of the first step).
_LatticeState = tuple[Lattice, tuple[Any, Any], Any, Any]


class BitReversible(
    AbstractSplittingMethod, AbstractTimeReversible, AbstractSolver[_LatticeState]
):
    r"""A palindromic splitting method run on an integer lattice: bit-reversible
    (module docstring).

    ```python
    solver = lj.BitReversible(lj.Yoshida4())
    traj = lj.simulate(kepler, y0, t1=1e3, dt=1e-3, solver=solver,
                       adjoint=lj.ReversibleAdjoint())  # no checkpoints needed
    ```

    **Arguments:**

    - `method`: a palindromic splitting (`StormerVerlet`, `Yoshida4`, `KahanLi8`,
      `BlanesMoan4`, …) whose table is run; its `compensated` flag is moot here.
    - `q_range`, `p_range`: the largest |q| and |p| component the run may reach
      (None: `headroom` × the largest of y0's, leaf by leaf).
    - `headroom`: the default range over y0's magnitude (1024: float64's
      precision at y0's scale, room for a thousandfold growth).

    ??? cite "References"

        - Levesque & Verlet, *Molecular dynamics and time reversibility*,
          J. Stat. Phys. 72, 519 (1993).
        - Rein & Tamayo, *JANUS: a bit-wise reversible integrator for N-body
          dynamics*, MNRAS 473, 3351 (2018).
    """

    method: AbstractSplittingSolver
    q_range: float | None = eqx.field(default=None, static=True)
    p_range: float | None = eqx.field(default=None, static=True)
    headroom: float = eqx.field(default=1024.0, static=True)
    term_structure: ClassVar = (AbstractTerm, AbstractTerm)
    interpolation_cls: ClassVar[Callable[..., LocalLinearInterpolation]] = (
        LocalLinearInterpolation
    )

    def __check_init__(self):
        if not isinstance(self.method, AbstractSplittingSolver):
            raise TypeError(
                "BitReversible runs a splitting table (StormerVerlet, Yoshida4, "
                f"KahanLi8, BlanesMoan4, ...), got {type(self.method).__name__}"
            )
        tables = (self.method.kick_coefficients, self.method.drift_coefficients)
        if any(tuple(table) != tuple(reversed(table)) for table in tables):
            raise ValueError(
                f"BitReversible needs a palindromic table (exactly), and "
                f"{type(self.method).__name__}'s is not: its step back would not "
                "undo its step"
            )
        for name, value in (("q_range", self.q_range), ("p_range", self.p_range)):
            if value is not None and not value > 0:
                raise ValueError(f"{name} must be a positive magnitude, got {value}")
        if not self.headroom >= 1:
            raise ValueError(f"headroom must be at least 1, got {self.headroom}")

    @property
    def needs_quadratic_kinetic(self) -> bool:  # pyright: ignore[reportIncompatibleVariableOverride]
        return self.method.needs_quadratic_kinetic

    def is_bit_reversible(self) -> bool:
        """Exactly reversible for an autonomous H (module docstring)."""
        return True

    def order(self, terms: Any) -> int | None:
        return self.method.order(terms)

    def lattice(self, y0: Any) -> Lattice:
        """The lattice for a run from `y0 = (q0, p0)`."""
        q0, p0 = y0
        return Lattice(
            jax.tree_util.tree_map(
                lambda x: lattice_spacing(x, self.q_range, self.headroom), q0
            ),
            jax.tree_util.tree_map(
                lambda x: lattice_spacing(x, self.p_range, self.headroom), p0
            ),
        )

    def init(self, terms, t0, t1, y0, args) -> _LatticeState:
        if not jax.config.read("jax_enable_x64"):
            # Without x64, JAX makes int64 arrays int32: the lattice would wrap.
            raise ValueError(
                "BitReversible keeps q and p as int64 lattice units, which needs "
                'jax.config.update("jax_enable_x64", True)'
            )
        lattice = self.lattice(y0)
        units = lattice.encode(y0)
        force = self._force_at(terms, t0, y0, lattice, units, args)
        nominal = jax.lax.stop_gradient(jnp.abs(jnp.asarray(t1 - t0)))
        return lattice, units, force, nominal

    @staticmethod
    def _force_at(terms, t, y, lattice: Lattice, units, args):
        """The force at the lattice point, with the derivative of the force at
        y's q (straight through the rounding: the point is exactly the lattice's,
        the step back ends at the same force)."""
        q = jax.tree_util.tree_map(
            lambda x, on: on + (x - jax.lax.stop_gradient(x)),
            y[0],
            lattice.decode_q(units[0]),
        )
        return terms[1].vf(t, q, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        lattice, units, force, nominal = solver_state
        if made_jump is not False:
            # After a jump y0 and the vector field may have changed: back on the lattice.

            def back_on_the_lattice():
                moved = lattice.encode(y0)
                return moved, self._force_at(terms, t0, y0, lattice, moved, args)

            units, force = jax.lax.cond(
                made_jump, back_on_the_lattice, lambda: (units, force)
            )
        params, static = eqx.partition((terms, args), eqx.is_inexact_array)
        y1, force, units, overflow = _straight_through_step(
            y0, force, params, (t0, t1, nominal), units, lattice, method=self.method,
            static=static,
        )  # fmt: skip
        # Off the lattice the values mean nothing: poisoned, the run stops there as
        # a non-finite state (the message names the lattice's range among the
        # causes).
        y1 = jax.tree_util.tree_map(
            lambda x, off: jnp.where(off, jnp.nan, x), y1, overflow
        )
        return (
            y1,
            None,
            dict(y0=y0, y1=y1),
            (lattice, units, force, nominal),
            RESULTS.successful,
        )

    def func(self, terms, t0, y0, args):
        term_q, term_p = terms
        q0, p0 = y0
        return term_q.vf(t0, p0, args), term_p.vf(t0, q0, args)
