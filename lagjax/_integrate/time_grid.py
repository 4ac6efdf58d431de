"""The exact time grid of fixed-step runs: every step the same h, to the last bit.

A fixed-step solver is handed (t_k, t_{k+1}) and takes h = t_{k+1} − t_k. When the
grid times are rounded — t0 + k·dt with dt = 1/60, or diffrax's
t0 + (t1 − t0)·k/n — h wobbles by an ulp of t from step to step. For a symplectic
method a varying step is a different map each step, and the modified energy it
conserves random-walks with the wobble: on Störmer–Verlet over 6·10⁵ steps of
the oscillator, 7e-12 instead of 3.5e-16 (`tests/test_simulate.py`). `grid_step`
rounds dt so that every t0 + k·dt is exact, and the scan paths (`fixed_step.py`,
`scan_saving.py`: every fixed-step run diffeqsolve does not take) form their times
that way. Save times off that grid are read from the continuous extension
(`lagjax.solvers.hermite`) of the step they fall in, to the method's order; the rounded
dt moves a save time meant for the user's grid by up to k·ulp into a neighbouring
step, where the extension is exact to round-off at its end.

References: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
Springer (2006), §VIII.5 (round-off and Brouwer's law), §VIII.2 (variable steps
destroy the modified-energy conservation).
"""

from __future__ import annotations

from typing import Any

import numpy as np


def grid_step(t0: float, t1: float, dt: float, dtype: Any = float) -> float:
    """`dt` rounded so that every grid time t0 + k·dt is exact in `dtype`.

    A solver takes its step as h = t_{k+1} − t_k. With a dt like 1/60 the grid times
    round differently from step to step, h wobbles by an ulp of t, and that
    non-constant step breaks the time-symmetry of symplectic methods: their
    round-off then grows like n^0.75 instead of Brouwer's √n (measured in
    `benchmarks/stability_brouwer.py`). Rounded to a multiple of the ulp of the
    largest grid time, dt makes every t0 + k·dt — and so every h — exact, when t0
    itself lies on that grid (0, integers, …). The change is at most
    n·ε/2 relative for n steps; when it would exceed 1e-8 (float32 runs, or t0 off
    the grid) dt is left alone.
    """
    largest = max(abs(t0), abs(t1), abs(dt))
    quantum = float(np.spacing(np.asarray(largest, dtype=dtype)))
    rounded = round(dt / quantum) * quantum
    exact_start = (t0 / quantum).is_integer()
    if rounded == 0 or not exact_start or abs(rounded - dt) > 1e-8 * abs(dt):
        return dt
    return rounded
