"""Progress of a long sweep: members done, rate and time left, once per chunk.

`sweep_to_disk(..., progress=True)` prints one line per chunk; a callable receives
a `SweepProgress` instead (and may raise to stop the sweep: the chunks written so
far stay, and the same call resumes after them). The rate counts only the members
this process integrated during this call — resumed chunks cost nothing — and the
first chunk's rate includes compilation.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Callable
from typing import Any


@dataclasses.dataclass(frozen=True)
class SweepProgress:
    """Where a sweep stands after one more chunk (of this process).

    - `chunk`: the index of the chunk just written.
    - `members_done`: members of the sweep in completed chunks, as this process
      knows them (all processes' chunks finished before this call, and its own).
    - `members_total`: the sweep's size.
    - `members_this_call`: members this process integrated during this call.
    - `rate`: `members_this_call` per second of this call.
    - `seconds_left`: this process's remaining members at that rate.
    - `failed`: members of completed chunks whose `RESULTS` code is a failure.
    - `process`, `process_count`: which of JAX's processes reports.
    """

    chunk: int
    members_done: int
    members_total: int
    members_this_call: int
    rate: float
    seconds_left: float
    failed: int
    process: int
    process_count: int

    def line(self) -> str:
        where = (
            f" [process {self.process}/{self.process_count}]"
            if self.process_count > 1
            else ""
        )
        return (
            f"sweep: {self.members_done}/{self.members_total} members "
            f"(chunk {self.chunk} written), {self.rate:.4g} members/s, "
            f"{self.seconds_left:.1f} s left, {self.failed} failed{where}"
        )


def _print_line(report: SweepProgress) -> None:
    print(report.line(), file=sys.stderr, flush=True)


class ProgressMeter:
    """Counts members as chunks complete and hands each report to `report`."""

    def __init__(
        self,
        progress: bool | Callable[[SweepProgress], Any],
        members_total: int,
        members_done: int,
        members_mine: int,
        failed: int,
        process: int,
        process_count: int,
    ):
        if progress is True:
            self.report = _print_line
        elif progress is False or progress is None:
            self.report = None
        elif callable(progress):
            self.report = progress
        else:
            raise TypeError(f"progress must be a bool or a callable, got {progress!r}")
        self.members_total = members_total
        self.members_done = members_done
        self.members_left_mine = members_mine
        self.members_this_call = 0
        self.failed = failed
        self.where = (process, process_count)
        self.start = time.perf_counter()

    def chunk_written(self, chunk: int, members: int, failed: int) -> None:
        self.members_done += members
        self.members_this_call += members
        self.members_left_mine -= members
        self.failed += failed
        if self.report is None:
            return
        elapsed = max(time.perf_counter() - self.start, 1e-9)
        rate = self.members_this_call / elapsed
        left = self.members_left_mine / rate if rate > 0 else math.inf
        self.report(
            SweepProgress(
                chunk,
                self.members_done,
                self.members_total,
                self.members_this_call,
                rate,
                left,
                self.failed,
                *self.where,
            )
        )
