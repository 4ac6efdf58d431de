"""Timing a run that returns a state (q, p): its first call, with compilation, and
the median of repeated later calls, each computed to the end (the runs return
NumPy arrays, so the work is done when they return)."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np


def timed(run: Callable[[], tuple[np.ndarray, np.ndarray]], repeats: int) -> tuple:
    """(q, p, first call s, median of `repeats` later calls s)."""
    start = time.perf_counter()
    q, p = run()
    first = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        q, p = run()
        times.append(time.perf_counter() - start)
    return q, p, first, statistics.median(times)
