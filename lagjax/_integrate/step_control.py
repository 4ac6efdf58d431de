"""How a run steps: fixed `dt` or a step-size controller, and the defaults filled in.

`simulate` accepts a fixed step, diffrax's adaptive PID control from `rtol`/`atol`,
or any diffrax step-size controller the caller passes; this module turns those into
diffrax's `(controller, dt0)`, refuses the pairings that cannot work (an adaptive
controller with a solver that makes no error estimate), fills in what the caller
left out (t1 = 10, or a scene's own span and step), and gives diffrax's implicit
solvers tolerances when no adaptive controller supplies them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import diffrax
import equinox as eqx
import jax
import numpy as np
import optimistix as optx

from lagjax._core.system import DEFAULT_T1, AbstractSystem


def with_implicit_tolerances(
    solver: diffrax.AbstractSolver, rtol: float, atol: float
) -> diffrax.AbstractSolver:
    """A diffrax implicit solver whose unset Newton tolerances are `rtol`, `atol`.

    diffrax's implicit solvers (Kvaerno5, …) take them from the adaptive step-size
    controller by default; with a fixed step there is none, so simulate's own
    tolerances stand in (the norm is then diffrax's RMS norm). Their default root
    finder, diffrax's `VeryChord`, is then `optimistix.Newton`: the chord
    iteration's divergence test (two successive corrections growing twofold)
    stopped Kvaerno5 on the 150° pendulum at dt = 0.01 with rtol ≤ 1e-8, where
    Newton converges, and a fixed-step run has no rejected step to recover by.
    """
    if not isinstance(solver, diffrax.AbstractImplicitSolver):
        return solver
    finder = solver.root_finder
    if type(finder) is diffrax.VeryChord and _unset(finder.rtol):
        return eqx.tree_at(
            lambda s: s.root_finder,
            solver,
            optx.Newton(rtol=rtol, atol=atol, norm=optx.rms_norm),
        )
    fills = {"rtol": rtol, "atol": atol, "norm": optx.rms_norm}
    unset = [
        name
        for name in fills
        if hasattr(finder, name) and _unset(getattr(finder, name))
    ]
    if not unset:
        return solver
    return eqx.tree_at(
        lambda s: [getattr(s.root_finder, name) for name in unset],
        solver,
        [fills[name] for name in unset],
    )


def _unset(value: Any) -> bool:
    """diffrax marks an unset root-finder tolerance with a sentinel object."""
    return not isinstance(value, (int, float, Callable))


def stepping(solver, t0, t1, dt, rtol, atol, controller=None):
    if controller is not None:
        return _checked_controller(solver, controller, dt), dt
    if dt is not None:
        return diffrax.ConstantStepSize(), dt
    if not isinstance(solver, diffrax.AbstractAdaptiveSolver):
        raise ValueError(
            f"{type(solver).__name__} has no error estimate, so it cannot choose its own "
            "step: pass dt."
        )
    return diffrax.PIDController(rtol=rtol, atol=atol), None


def _checked_controller(solver, controller, dt):
    """The caller's step-size controller, refused where it cannot work."""
    if not isinstance(controller, diffrax.AbstractStepSizeController):
        raise TypeError(
            "stepsize_controller must be a diffrax step-size controller "
            "(diffrax.PIDController, ConstantStepSize, StepTo, …), got "
            f"{type(controller).__name__}"
        )
    adaptive = isinstance(controller, diffrax.AbstractAdaptiveStepSizeController)
    if adaptive and not isinstance(solver, diffrax.AbstractAdaptiveSolver):
        raise ValueError(
            f"{type(controller).__name__} adapts the step to an error estimate, but "
            f"{type(solver).__name__} makes none: pass dt (fixed steps), "
            "diffrax.StepTo(ts=...), or an adaptive solver (Tsit5, Dopri8, Kvaerno5)"
        )
    if isinstance(controller, diffrax.StepTo) and dt is not None:
        raise ValueError(
            "diffrax.StepTo takes its steps from its own ts: leave dt unset (None)"
        )
    return controller


def defaults(system, t0, t1, dt, solver, controller, tolerance_run=False):
    """`(t1, dt)` with what the caller left out filled in.

    t1 = 10 for a plain system. A scene supplies its own span, and its own step
    unless the caller asked for adaptive stepping (an adaptive solver, a step-size
    controller, or a tolerance with no solver: `tolerance_run`):
    `simulate(scene, scene.initial_state())` is then the scene's
    default run — its default solver (`solver_choice.default_solver`) at its `default_dt` — as the
    command line does it.
    """
    if not isinstance(system, AbstractSystem):  # refused by name in the checks
        return (DEFAULT_T1 if t1 is None else t1), dt
    default_t1, default_dt = system.default_span()
    if t1 is None:
        t1 = default_t1
    if default_dt is None:
        return t1, dt
    adaptive = (
        tolerance_run
        or controller is not None
        or isinstance(solver, diffrax.AbstractAdaptiveSolver)
    )
    if dt is None and not adaptive:
        dt = default_dt
        ends = [as_python_number(x) for x in (t0, t1)]
        if all(isinstance(x, (int, float)) for x in ends) and ends[1] < ends[0]:
            dt = -dt  # a backward run steps backward
    return t1, dt


def as_python_number(x: Any) -> Any:
    """A concrete NumPy/JAX scalar as a Python float (traced values are kept)."""
    if isinstance(x, (np.generic, np.ndarray)) and np.ndim(x) == 0:
        return float(x)
    if isinstance(x, jax.Array) and x.ndim == 0:
        try:
            return float(x)
        except jax.errors.ConcretizationTypeError:  # traced: keep it traced
            return x
    return x


def diffrax_step_bound(t0, t1, dt) -> int | None:
    """An upper bound on the steps diffrax's loop takes over [t0, t1] at `dt` (its
    `max_steps`), or None for traced times. Unlike `fixed_step_count` (the exact
    count of the scan, which forgives a ratio off an integer by 1e-9), it rounds
    up past any round-off of the accumulated times and adds one step."""
    if dt is None or not all(isinstance(x, (int, float)) for x in (t0, t1, dt)):
        return None
    return math.ceil(abs((t1 - t0) / dt) * (1 + 1e-12)) + 1
