"""The state of a run at any time, and event functions, in the caller's convention.

`simulate` may integrate another state than the caller's `y0`: one flat vector
(`lagjax._integrate.flat_state`), or (q, p) of a Lagrangian's Legendre transform for a
symplectic method. diffrax's dense output and event conditions see that integrated
state; `UserState` turns it back into `y0`'s convention — (q, q̇) for a
Lagrangian, (q, p) for a Hamiltonian — through the system interface
(`AbstractSystem.state_velocity` / `state_momentum`). `DenseSolution` evaluates the
run's continuous extension (`lagjax.solvers.hermite` for fixed-step solvers) and
`UserStateCondition` hands an event's condition the caller's state.
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from lagjax._core.system import AbstractSystem
from lagjax._integrate.flat_state import FlatState


class UserState(eqx.Module):
    """Integrated state → the caller's `(q, q̇)` or `(q, p)`."""

    flat: FlatState | None
    integrated: AbstractSystem
    # True: the caller wants p, False: q̇, None: the integrated state already is it.
    wants_momentum: bool | None = eqx.field(static=True)

    @classmethod
    def of(cls, flat, integrated: AbstractSystem, user: AbstractSystem) -> UserState:
        same = integrated.second_is_momentum == user.second_is_momentum
        return cls(flat, integrated, None if same else user.second_is_momentum)

    def __call__(self, t: Any, y: Any, args: Any) -> tuple[Any, Any]:
        if self.flat is not None:
            y = self.flat.unravel(y)
        if self.wants_momentum is None:
            return y
        q, second = y
        convert = (
            self.integrated.state_momentum
            if self.wants_momentum
            else self.integrated.state_velocity
        )
        return q, convert(q, second, t, args)


class UserStateCondition(eqx.Module):
    """An event condition `fn(t, y, args, **kwargs)` fed the caller's state."""

    fn: Any
    user_state: UserState

    def __call__(self, t, y, args, **kwargs):
        return self.fn(t, self.user_state(t, y, args), args, **kwargs)


def event_in_user_state(
    event: diffrax.Event, user_state: UserState, dtype: Any
) -> diffrax.Event:
    """`event` with its conditions fed the caller's state, and a root finder.

    Without a root finder diffrax stops at the end of the step where the condition
    changed sign; lagjax locates the crossing on the dense output instead, with
    Newton's method to a few ulps of the time (`optimistix.Newton`).
    """
    if not isinstance(event, diffrax.Event):
        raise TypeError(
            f"event must be a diffrax.Event (diffrax.Event(cond_fn)), got "
            f"{type(event).__name__}"
        )
    conditions = jax.tree_util.tree_map(
        lambda fn: UserStateCondition(fn, user_state),
        event.cond_fn,
        is_leaf=callable,
    )
    root_finder = event.root_finder
    if root_finder is None:
        tolerance = 100 * float(jnp.finfo(dtype).eps)
        root_finder = optx.Newton(rtol=tolerance, atol=tolerance)
    return diffrax.Event(conditions, root_finder, event.direction)


class DenseSolution(eqx.Module):
    """A run's continuous extension, evaluated in the caller's convention."""

    interpolation: diffrax.DenseInterpolation
    user_state: UserState
    args: Any

    def evaluate(self, t: Any) -> tuple[Any, Any]:
        """The state at time(s) `t` within the span; a leading axis for an array."""
        t = jnp.asarray(t)
        if t.ndim:
            return jax.vmap(self.evaluate)(t)
        start, end = self.interpolation.t0, self.interpolation.t1
        low, high = jnp.minimum(start, end), jnp.maximum(start, end)
        slack = 1e-12 * (high - low)
        t = eqx.error_if(
            t,
            (t < low - slack) | (t > high + slack),
            "Trajectory.evaluate: t lies outside the integrated span; the dense "
            "output covers [t0, t1] (or up to the event that ended the run)",
        )
        return self.user_state(t, self.interpolation.evaluate(t), self.args)
