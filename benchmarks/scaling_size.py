r"""How costs grow with the number of coordinates: lagjax against SymPy.

An n-link pendulum (unit masses and rods, all links released at rest from 0.5 rad)
and a 100-particle Fermi–Pasta–Ulam chain. For lagjax the "build" time is tracing —
which includes the derivation by autodiff — plus XLA compilation of `lj.simulate`;
the run is adaptive Dopri8 at rtol = atol = `TOLERANCE`. For SymPy the build is
`LagrangesMethod` and `lambdify`, in two variants: M and f lambdified and
M q̈ = f solved numerically at every call (`peers.derive_with_sympy`), and q̈
solved by SymPy itself (`LagrangesMethod.rhs`), whose expressions swell with n.
Both run in scipy's DOP853 at the same tolerance, capped by a time budget (see
`scaling.py`).

References: SymPy documentation, `sympy.physics.mechanics.LagrangesMethod`.
"""

from __future__ import annotations

import time
from typing import Any

import diffrax
import jax.numpy as jnp
import numpy as np

import lagjax as lj
from benchmarks import peers
from lagjax import diagnostics
from lagjax.scenes.chains import FermiPastaUlamChain

TOLERANCE = 1e-8
PENDULUM_T1, CHAIN_T1 = 2.0, 10.0
ONCE = dict(repeats=1)  # for runs that take many seconds


def n_link_pendulum_lagrangian(m: Any, q: Any, qd: Any, gravity: float = 9.81):
    """n unit masses on n unit rods, angles from the downward vertical.

    Written once for both backends: `m` is jax.numpy (lagjax) or sympy; `q`, `qd`
    are indexed by link.
    """
    x_dot = y_dot = height = kinetic = potential = 0
    for k in range(len(qd)):
        x_dot = x_dot + m.cos(q[k]) * qd[k]
        y_dot = y_dot + m.sin(q[k]) * qd[k]
        height = height - m.cos(q[k])
        kinetic = kinetic + (x_dot**2 + y_dot**2) / 2
        potential = potential + gravity * height
    return kinetic - potential


def lagjax_row(system: Any, y0: Any, t1: float, args: Any, timing: dict) -> dict:
    def run(y0):
        trajectory = lj.simulate(
            system, y0, t1=t1, solver=diffrax.Dopri8(), args=args,
            rtol=TOLERANCE, atol=TOLERANCE, max_steps=10**6,
        )  # fmt: skip
        return trajectory.q[-1], trajectory.stats["num_steps"]

    measured = diagnostics.time_run(run, y0, **timing)
    return dict(
        build_s=measured.compile_seconds,
        run_s=measured.run_seconds,
        steps=int(measured.output[1]),
    )


def scipy_row(route: peers.NumpyRoute, t1: float, timing: dict) -> dict:
    from scipy.integrate import solve_ivp

    def run():
        return solve_ivp(
            route.rhs, (0.0, t1), route.initial_state, method="DOP853",
            rtol=TOLERANCE, atol=TOLERANCE,
        )  # fmt: skip

    measured = diagnostics.time_run(run, jit=False, warmup=0, **timing)
    return dict(
        build_s=route.derivation_seconds,
        run_s=measured.run_seconds,
        steps=len(measured.output.t) - 1,
        evaluations=int(measured.output.nfev),
    )


def derive_symbolic_rhs(size: int) -> tuple[Any, float]:
    """q̈ solved by SymPy (`LagrangesMethod.rhs`) and lambdified: (f, seconds)."""
    import sympy as sp
    import sympy.physics.mechanics  # loaded before the clock starts

    start = time.perf_counter()
    method, symbols, plain = peers.lagranges_equations(n_link_pendulum_lagrangian, size)
    rhs = sp.lambdify(symbols, method.rhs().subs(plain), "numpy")
    return rhs, time.perf_counter() - start


def _numpy_route(rhs: Any, start: np.ndarray, seconds: float) -> peers.NumpyRoute:
    return peers.NumpyRoute(rhs, start, lambda xp, y: y, seconds)


def measured_or_estimated(
    route: peers.NumpyRoute, t1: float, like: dict, budget: float
) -> dict:
    """scipy DOP853 on `route`; or, when one evaluation (median of three) times the
    evaluation count of `like` — the same equations at the same tolerance — exceeds
    budget/4, that product, marked as an estimate."""
    call = diagnostics.time_run(
        route.rhs, 0.0, route.initial_state, jit=False, warmup=0, repeats=3
    )
    estimate = call.run_seconds * like["evaluations"]
    if estimate >= budget / 4:
        return dict(build_s=route.derivation_seconds, run_s=estimate,
                    steps=like["steps"], estimated=True)  # fmt: skip
    return dict(scipy_row(route, t1, ONCE), estimated=False)


def symbolic_row(size: int, numeric: dict, budget: float) -> dict:
    """SymPy solving for q̈ itself: its build time, and its run time."""
    rhs, seconds = derive_symbolic_rhs(size)
    start = np.concatenate([np.full(size, 0.5), np.zeros(size)])

    def field(t, y):
        return np.concatenate([y[size:], np.ravel(rhs(y[:size], y[size:]))[size:]])

    route = _numpy_route(field, start, seconds)
    return measured_or_estimated(route, PENDULUM_T1, numeric, budget)


def _next_exceeds(times: list[float], budget: float) -> bool:
    """Whether the next derivation, extrapolated geometrically, exceeds `budget`."""
    if not times:
        return False
    growth = times[-1] / times[-2] if len(times) > 1 and times[-2] > 0 else 2.0
    return times[-1] * max(growth, 1.0) > budget


def pendulum_scaling(sizes: range, budget: float, timing: dict) -> list[dict]:
    """lagjax and both SymPy variants for n-link pendulums of the given sizes."""
    rows: list[dict] = []
    built: dict[str, list[float]] = {"numeric": [], "symbolic": []}
    for n in sizes:
        lag = lj.Lagrangian(
            lambda q, qd: n_link_pendulum_lagrangian(jnp, q, qd),
            quadratic_in_velocity=True,
        )
        y0 = (jnp.full(n, 0.5), jnp.zeros(n))
        rows.append(
            dict(n=n, route="lagjax", **lagjax_row(lag, y0, PENDULUM_T1, None, timing))
        )
        if not (peers.have_sympy() and peers.have_scipy()):
            continue
        if _next_exceeds(built["numeric"], budget):
            continue
        rhs, seconds = peers.derive_with_sympy(n_link_pendulum_lagrangian, n)
        start = np.concatenate([np.full(n, 0.5), np.zeros(n)])
        numeric = scipy_row(_numpy_route(rhs, start, seconds), PENDULUM_T1, timing)
        built["numeric"].append(seconds)
        rows.append(dict(n=n, route="SymPy, numeric solve of M", **numeric))
        if not _next_exceeds(built["symbolic"], budget):
            symbolic = symbolic_row(n, numeric, budget)
            built["symbolic"].append(symbolic["build_s"])
            rows.append(dict(n=n, route="SymPy, symbolic rhs()", **symbolic))
    for row in rows:
        print(_row_line(dict(system=f"{row['n']}-link pendulum", **row)), flush=True)
    return [dict(system=f"{row['n']}-link pendulum", **row) for row in rows]


def _row_line(row: dict) -> str:
    note = " (estimated)" if row.get("estimated") else ""
    return (
        f"  {row['system']:22s} {row['route']:28s} build {row['build_s']:7.2f} s, "
        f"run {row['run_s']:9.2e} s{note}, steps {row['steps']}"
    )


def chain_scaling(timing: dict, with_sympy: bool, budget: float) -> list[dict]:
    """A 100-particle FPU chain: lagjax, hand-written diffrax and (full mode) SymPy."""
    chain = FermiPastaUlamChain(frequency=50.0, pairs=50)
    system: dict[str, Any] = dict(system="FPU chain, 100 particles", n=100)
    rows: list[dict[str, Any]] = [
        dict(
            system,
            route="lagjax",
            **lagjax_row(chain, chain.initial_state(), CHAIN_T1, None, timing),
        )
    ]
    peer = peers.fermi_pasta_ulam(chain)
    final = peers.diffrax_final(peer, diffrax.Dopri8(), CHAIN_T1, TOLERANCE)
    measured = diagnostics.time_run(final, jnp.asarray(peer.initial_state), **timing)
    rows.append(dict(system, route="hand-written diffrax", build_s=measured.compile_seconds,
                     run_s=measured.run_seconds, steps=-1))  # fmt: skip
    if with_sympy and peers.have_sympy() and peers.have_scipy():
        hand = scipy_row(peers.hand_written_numpy(peer), CHAIN_T1, timing)
        rows.append(dict(system, route="scipy DOP853, hand-written numpy", **hand))
        route = peers.sympy_numpy(peer)
        sympy = measured_or_estimated(route, CHAIN_T1, hand, budget)
        rows.append(dict(system, route="SymPy, numeric solve of M", **sympy))
    for row in rows:
        print(_row_line(row), flush=True)
    return rows
