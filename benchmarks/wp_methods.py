"""The lines of a work-precision diagram: each solver or peer, swept and runnable.

A `Method` is one line — a solver swept over step counts or tolerances — and its
`runner(value)` makes one timed point, a `Runner`: the call to time, and how to
turn its output into (final comparable state, states for the energy error, steps).
lagjax runs through `lj.simulate`; the peers (`peers.py`) through
`diffrax.diffeqsolve` on hand-written equations, and scipy's `solve_ivp` on
hand-written numpy or on the SymPy-derived right-hand side. The energy error comes
from a second, untimed run saved at `ENERGY_SAMPLES` stratified random times.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from benchmarks import peers
from benchmarks.wp_cases import Case
from lagjax import diagnostics

ENERGY_SAMPLES = 200  # stratified random save times (diagnostics.sample_times)


@dataclass(frozen=True)
class Runner:
    """One timed point, `fn(*args)`, and `finish(output)` → (final, series, steps)."""

    fn: Callable[..., Any]
    args: tuple
    jit: bool
    finish: Callable[[Any], tuple[np.ndarray, np.ndarray, int]]
    setup_seconds: float = 0.0


@dataclass(frozen=True)
class Method:
    """One line of a work-precision diagram: a solver swept over `values`."""

    label: str
    family: str  # lagjax | diffrax | scipy | sympy
    parameter: str  # steps | rtol
    values: tuple[float, ...]
    runner: Callable[[float], Runner]


def simulate_case(case, solver, y0, setting, fixed, saved, max_steps):
    """Comparable states at `saved` (or the end) and the step count, by lj.simulate."""
    kwargs = dict(dt=setting) if fixed else dict(rtol=setting, atol=setting)
    system = case.scene if case.system is None else case.system
    trajectory = lj.simulate(
        system, y0, t1=case.t1, solver=solver, ts=saved, max_steps=max_steps, **kwargs
    )
    return case.states(trajectory), trajectory.stats["num_steps"]


def lagjax_method(case: Case, name: str, solver: Any, fixed: bool, values) -> Method:
    """lagjax on the case; a second, untimed run saves states for the energy error."""
    longest = int(max(values)) + 2 if fixed else 10**6

    def run(y0, setting, ts):
        limit = None if (fixed and ts is None) else longest  # None: the scan path
        return simulate_case(case, solver, y0, setting, fixed, ts, limit)

    probe = jax.jit(lambda y0, setting, ts: run(y0, setting, ts)[0])

    def runner(value: float) -> Runner:
        setting = case.t1 / value if fixed else value
        dt = setting if fixed else None
        saved = diagnostics.sample_times(0.0, case.t1, ENERGY_SAMPLES, dt)

        def finish(output):
            series = np.asarray(probe(case.start(), setting, saved))
            return np.asarray(output[0][-1]), series, int(output[1])

        return Runner(lambda y0: run(y0, setting, None), (case.start(),), True, finish)

    kind = "steps" if fixed else "rtol"
    return Method(f"lagjax {name}", "lagjax", kind, tuple(values), runner)


def diffrax_method(case: Case, name: str, solver: Any) -> Method:
    saved = diagnostics.sample_times(0.0, case.t1, ENERGY_SAMPLES)
    y0 = jnp.asarray(case.peer.initial_state)
    # rtol traced: one compilation of the (untimed) energy run serves every point.
    probe = jax.jit(
        lambda y0, rtol: peers.diffrax_final(case.peer, solver, case.t1, rtol, saved)(
            y0
        )
    )

    def runner(value: float) -> Runner:
        def finish(output):
            return np.asarray(output), np.asarray(probe(y0, value)), -1

        final = peers.diffrax_final(case.peer, solver, case.t1, value)
        return Runner(final, (y0,), True, finish)

    label = f"diffrax {name} (hand-written)"
    return Method(label, "diffrax", "rtol", case.peer_tolerances, runner)


def scipy_method(case: Case, family: str, method: str, route_of) -> Method:
    routes: list[peers.NumpyRoute] = []  # SymPy derives once per scene, when first run

    def runner(value: float) -> Runner:
        if not routes:
            routes.append(route_of(case.peer))
        route = routes[0]
        convert = jax.jit(jax.vmap(lambda y: route.comparable(jnp, y)))

        def finish(output):
            series = np.asarray(convert(jnp.asarray(output)))
            return series[-1], series, len(output) - 1

        run = peers.scipy_run(route, case.t1, method, value)
        return Runner(run, (), False, finish, route.derivation_seconds)

    # Implicit scipy methods at rtol below 1e-8 take minutes here: not swept there.
    tolerances = case.peer_tolerances[: 3 if method in ("LSODA", "Radau") else None]
    label = {
        "scipy": f"scipy {method} (hand-written numpy)",
        "sympy": f"SymPy LagrangesMethod → scipy {method}",
    }[family]
    return Method(label, family, "rtol", tolerances, runner)


def all_methods(case: Case, quick: bool) -> list[Method]:
    methods = [
        lagjax_method(case, name, solver, True, steps)
        for name, (solver, steps) in case.fixed.items()
    ] + [
        lagjax_method(case, name, solver, False, tolerances)
        for name, (solver, tolerances) in case.adaptive.items()
    ]
    for name in ("Dopri8",) if quick else ("Tsit5", "Dopri8"):
        methods.append(diffrax_method(case, name, getattr(diffrax, name)()))
    if not peers.have_scipy():
        print("  scipy is not installed: the scipy and SymPy peers are skipped")
        return methods
    for name in case.scipy_methods:
        methods.append(scipy_method(case, "scipy", name, peers.hand_written_numpy))
    if not peers.have_sympy():
        print("  sympy is not installed: the SymPy route is skipped")
    elif case.peer.sympy_lagrangian is not None:
        methods.append(scipy_method(case, "sympy", "DOP853", peers.sympy_numpy))
    return methods
