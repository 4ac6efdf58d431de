"""The time-transformed run's steps in double-double arithmetic.

`TimeTransformed(..., precision="double-double")` keeps the extended state
((p, p_t), (q, t)) and the splitting's stored force as double-doubles
(`lagjax._linalg.double_double`) and runs each step — every drift and kick, the
user's T and V and their gradients — in double-double arithmetic, by evaluating
the float64 step's jaxpr on double-doubles. The loop around it is the float64
run's (`time_transformed_run`): it reads the time's high part to find the save
times. The partial step to a save time finds its length σ·ds by float64 secant
iterations from the recorded state rounded (a double-double copy of the step in
the iterations, under `vmap` over the saves, made the first call 20 s instead of
8), then takes that one step in double-double: in float64 that step's own
round-off, 2/(1 − e) times enlarged, read 1.1e-12 at e = 0.999.

Why: the method keeps its log Hamiltonian Γ exactly in exact arithmetic, so in
float64 its only error in Γ is round-off, a random walk of about √n ε over n
steps, which an eccentric orbit's pericentre magnifies by 2/(1 − e) in the
energy. Kahan's compensated sum (the splitting's default) removes the rounding
of the state's update but not that of the increment itself, and near the
pericentre a step moves the state by about its own size. In double-double both
are 2⁻¹⁰⁶ instead of 2⁻⁵³. Each step runs uncompensated: the double-double sum
already keeps the increments' low-order bits.

References: Mikkola & Tanikawa, Celest. Mech. 74, 287 (1999); Hairer, McLachlan
& Razakarivony, "Achieving Brouwer's law with implicit Runge–Kutta methods",
BIT 48, 231 (2008) (round-off in long integrations).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax.numpy as jnp

from lagjax._linalg.double_double import in_double_double, split_tree


def double_double_steps(terms: Any, splitting: Any, args: Any):
    """`(advance, one_step, start)` in the float64 run's shapes, in double-double:
    `advance(y, solver_state, ds) -> (y1, solver_state1, ds, True)`,
    `one_step(y, h) -> y1` and `start(state0) -> (y0, solver_state0)`."""
    if getattr(splitting, "compensated", False):
        splitting = dataclasses.replace(splitting, compensated=False)

    def init(y: Any) -> Any:
        zero = jnp.zeros((), jnp.result_type(y[1][1]))
        return splitting.init(terms, zero, zero, y, args)

    def step(y: Any, solver_state: Any, h: Any) -> tuple[Any, Any]:
        zero = jnp.zeros((), h.dtype)
        y1, _, _, solver_state1, _ = splitting.step(
            terms, zero, h, y, args, solver_state, False
        )
        return y1, solver_state1

    init_dd, step_dd = in_double_double(init), in_double_double(step)

    def advance(y: Any, solver_state: Any, ds: Any):
        y1, solver_state1 = step_dd(y, solver_state, ds)
        return y1, solver_state1, ds, True

    def one_step(y: Any, h: Any) -> Any:
        return step_dd(y, init_dd(y), h)[0]

    def start(state0: Any) -> tuple[Any, Any]:
        y0 = split_tree(state0)
        return y0, init_dd(y0)

    return advance, one_step, start
