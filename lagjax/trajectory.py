"""`Trajectory`: the saved states of a run and the quantities derived from them.

Only the integrated state is stored — (q, q̇) for a Lagrangian integrated directly,
(q, p) for a Hamiltonian (including a Lagrangian integrated through its Legendre
transform). The other of q̇ and p, and the energy, are derived on demand by the
system the state belongs to (`AbstractSystem.state_velocity`, …).
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

from lagjax._core.system import AbstractSystem


class Trajectory(eqx.Module):
    """Saved times `ts` and states `ys = (q, q̇ or p)`; arrays have a leading time axis.

    For a `RigidBody`, q is the unit quaternion, p the body angular momentum and q̇
    the quaternion's rate.

    `stats` holds the solver used, diffrax's step counts and whether the state stayed
    finite; `result` is diffrax's `RESULTS` value (successful or why not, or
    `event_occurred` for a run an event ended). `dense_output` is the run's
    continuous extension when `simulate(..., dense=True)` kept it (`evaluate`).
    """

    ts: jax.Array
    ys: tuple[Any, Any]
    system: AbstractSystem
    args: Any
    run_stats: dict[str, Any]
    result: diffrax.RESULTS
    solver_name: str = eqx.field(static=True)
    dense_output: Any = None

    def evaluate(self, t: Any) -> tuple[Any, Any]:
        """The state at time(s) `t` of the span, in `y0`'s convention: (q, q̇) for a
        Lagrangian, (q, p) for a Hamiltonian, whatever state was integrated.

        Needs `simulate(..., dense=True)` (or `saveat=diffrax.SaveAt(dense=True)`);
        between steps of a fixed-step solver it is the Hermite extension of
        `lagjax.solvers.hermite`. An array `t` gives arrays with a leading time axis.
        A time that is not finite (NaN, inf) or lies outside the span is refused: a
        concrete one here, a traced one by a run-time error (`eqx.error_if`).
        """
        if self.dense_output is None:
            raise ValueError(
                "this trajectory kept no dense output: run simulate(..., dense=True) "
                "to evaluate it between saved times"
            )
        return self.dense_output.evaluate(_finite_times(t))

    @property
    def stats(self) -> dict[str, Any]:
        return {"solver": self.solver_name, **self.run_stats}

    @property
    def is_hamiltonian(self) -> bool:
        """True when the second state component is a momentum (not q̇)."""
        return self.system.second_is_momentum

    @property
    def q(self) -> Any:
        return self.ys[0]

    def _along(self, fn):
        """Apply fn(q, second, t, args) at every saved time (and batch member).

        A batched trajectory (from `lj.sweep` or `jax.vmap` of `simulate`) has extra
        leading axes on `ts`, the states and `args`; each is mapped over.
        """

        def along_time(q, second, ts, args):
            return jax.vmap(fn, in_axes=(0, 0, 0, None))(q, second, ts, args)

        mapped = along_time
        for _ in range(jnp.ndim(self.ts) - 1):
            mapped = jax.vmap(mapped)
        return mapped(self.ys[0], self.ys[1], self.ts, self.args)

    @property
    def qdot(self) -> Any:
        if not self.is_hamiltonian:  # the state holds q̇: no eager vmap (~1 ms)
            return self.ys[1]
        return self._along(self.system.state_velocity)

    @property
    def p(self) -> Any:
        if self.is_hamiltonian:  # the state holds p
            return self.ys[1]
        return self._along(self.system.state_momentum)

    def energy(self) -> jax.Array:
        """H(q, p, t) or the Jacobi integral h(q, q̇, t) at every saved time."""
        return self._along(self.system.state_energy)


def _finite_times(t: Any) -> Any:
    """`t` if every entry is finite; NaN compares false with both ends of the span,
    so the span check alone would let it through as a NaN state."""
    remedy = "evaluate at finite times inside the run's span [t0, t1]"
    if isinstance(t, Tracer):
        return eqx.error_if(
            t, ~jnp.isfinite(t), f"Trajectory.evaluate: t is NaN or inf; {remedy}"
        )
    values = np.asarray(t)
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        where = "t" if values.ndim == 0 else f"t[{bad[0]}]"
        shown = values.reshape(-1)[bad[0]]
        raise ValueError(
            f"Trajectory.evaluate: {where} = {shown} is not a finite time; {remedy}"
        )
    return t
