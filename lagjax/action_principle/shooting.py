r"""Hamilton's principal function of the end points, by shooting.

$S(q_1, t_1; q_0, t_0)$ is the action of the true path from $q(t_0) = q_0$ to
$q(t_1) = q_1$. That path solves a two-point boundary-value problem; shooting turns
it into a root-finding problem for the free half $s$ of the initial state ($\dot
q_0$ for a Lagrangian, $p_0$ for a Hamiltonian):

$$ F(s; q_0, q_1) = q(t_1;\, q_0, s) - q_1 = 0 , $$

solved by Newton's method with the Jacobian $\partial q(t_1)/\partial s$ from
forward-mode autodiff through the integration. Then $S = $ `action` of the run.
`optimistix.root_find` differentiates the root by the implicit function theorem,
$ds/dq_1 = -(\partial F/\partial s)^{-1}\,\partial F/\partial q_1$, so `jax.grad`
of $S$ gives the Hamilton–Jacobi relations (the course text eq. 6.67–6.68)

$$ \frac{\partial S}{\partial q_1} = p_1, \qquad \frac{\partial S}{\partial q_0} =
   -p_0, \qquad \frac{\partial S}{\partial t_1} = -H_1 $$

to the accuracy of the run (the last through a time-rescaled L, whose duration is
a parameter: `tests/test_action.py`).

References: the course text §6.6; Goldstein, Poole & Safko, *Classical Mechanics*,
3rd ed., §10.1; Stoer & Bulirsch, *Introduction to Numerical Analysis*, 3rd ed.,
§7.3 (shooting methods).
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from lagjax._integrate.simulate import simulate
from lagjax.action_principle.hamilton_principle import (
    DEFAULT_NODES,
    System,
    action,
    resolve_system,
)
from lagjax.trajectory import Trajectory

# The Newton iteration solves the end-point miss to round-off.
_SHOOTING_TOLERANCE = 1e-12
_SHOOTING_MAX_STEPS = 32


def _straight_line_start(system, q0, q1, t0, t1, args):
    """The second initial-state component of the uniform straight line q0 → q1."""
    velocity = jax.tree_util.tree_map(lambda a, b: (b - a) / (t1 - t0), q0, q1)
    if not system.second_is_momentum:
        return velocity
    return system.path_lagrangian().momentum(q0, velocity, t0, args)


def _forward_differentiable(solver: Any) -> Any:
    """The solver with a Runge–Kutta stage loop that both autodiff modes accept.

    Newton's Jacobian of the end-point miss is taken in forward mode, and diffrax's
    default stage loop for Runge–Kutta methods ("checkpointed") supports reverse
    mode only; "bounded" supports both, so `jax.grad` and `jax.jacfwd` of the
    result work too.
    """
    if isinstance(solver, diffrax.AbstractRungeKutta) and solver.scan_kind is None:
        return eqx.tree_at(
            lambda s: s.scan_kind, solver, "bounded", is_leaf=lambda x: x is None
        )
    return solver


def trajectory_between(
    system: System,
    q0: Any,
    q1: Any,
    t0: float,
    t1: float,
    *,
    guess: Any = None,
    args: Any = None,
    samples: int = 65,
    solver: Any = None,
    adjoint: Any = None,
) -> Trajectory:
    r"""The true path from $q(t_0) = q_0$ to $q(t_1) = q_1$, by shooting.

    Newton's method (`optimistix.Newton`, to round-off) on the end-point miss
    $q(t_1; q_0, s) - q_1$ for the free half $s$ of the initial state: $\dot q_0$
    for a Lagrangian, $p_0$ for a Hamiltonian. The run uses `samples - 1` fixed
    steps of `solver` (None: `simulate`'s default) and is saved on that step grid.
    Differentiable in `q0`, `q1` and `args` by the implicit function theorem.

    **Arguments:**
    - `guess`: a start for $s$; default the uniform straight line $q_0 \to q_1$.
      Beyond the first conjugate point (e.g. $t_1 - t_0 \ge \pi/\omega$ for an
      oscillator) the path is not unique, and the guess picks one.
    - `t0`, `t1`: Python floats (the fixed-step loop needs concrete times).
    - `adjoint`: diffrax adjoint of the saved run: the default supports `jax.grad`
      of the result, `diffrax.ForwardMode()` supports `jax.jvp` / `jax.jacfwd`.

    **References:** Stoer & Bulirsch, *Introduction to Numerical Analysis*, 3rd
    ed., §7.3 (shooting methods).
    """
    system, args = resolve_system(system, args)
    if not all(isinstance(x, (int, float)) for x in (t0, t1)) or t0 == t1:
        raise ValueError(
            f"t0 and t1 must be distinct Python numbers, got t0={t0!r}, t1={t1!r}"
        )
    if samples < 2:
        raise ValueError(f"samples must be at least 2, got {samples}")
    dt = (t1 - t0) / (samples - 1)
    solver = _forward_differentiable(solver)
    if guess is None:
        guess = _straight_line_start(system, q0, q1, t0, t1, args)

    def end_miss(start_second, boundary):
        start, end = boundary
        run = simulate(
            system, (start, start_second), t0, t1, dt=dt, solver=solver, args=args
        )
        return jax.tree_util.tree_map(lambda reached, e: reached[-1] - e, run.q, end)

    newton = optx.Newton(rtol=_SHOOTING_TOLERANCE, atol=_SHOOTING_TOLERANCE)
    solution = optx.root_find(
        end_miss, newton, guess, args=(q0, q1), max_steps=_SHOOTING_MAX_STEPS
    )
    ts = jnp.linspace(t0, t1, samples)
    return simulate(
        system,
        (q0, solution.value),
        t0,
        t1,
        dt=dt,
        solver=solver,
        ts=ts,
        args=args,
        adjoint=adjoint,
    )


def action_between(
    system: System,
    q0: Any,
    q1: Any,
    t0: float,
    t1: float,
    *,
    guess: Any = None,
    args: Any = None,
    samples: int = 65,
    solver: Any = None,
    adjoint: Any = None,
    nodes: int = DEFAULT_NODES,
) -> jax.Array:
    r"""Hamilton's principal function $S(q_1, t_1; q_0, t_0)$: the action of the true path.

    The path is found by `trajectory_between` (same arguments) and its action by
    `action`. `jax.grad` with respect to `q1` gives the end momentum $p_1$ and with
    respect to `q0` gives $-p_0$ (Hamilton–Jacobi, the course text eq. 6.67).

    **References:** the course text §6.6; Goldstein, Poole & Safko §10.1.
    """
    path = trajectory_between(
        system,
        q0,
        q1,
        t0,
        t1,
        guess=guess,
        args=args,
        samples=samples,
        solver=solver,
        adjoint=adjoint,
    )
    return action(system, path, nodes=nodes)
