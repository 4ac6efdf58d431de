"""The plan of one `simulate` run: which loop integrates it and how it saves.

Decided in Python from the call's arguments, before the compiled call, and carried
into it as a static value (`RunPlan`). The decision, in one place:

| asked for | `Saving` | loop |
|---|---|---|
| fixed `dt`, the final state only | `FINAL_STATE` | one `lax.scan` over the solver's `step` (`fixed_step_loop.integrate_fixed_steps`) |
| fixed `dt`, `ts` on a uniform subgrid of the steps | `STEP_GRID` | nested scans saving every k-th step (`fixed_step_loop.integrate_fixed_steps_saving`) |
| fixed `dt`, `ts` between steps, `dense=True`, `SaveAt(steps=True)`, or `max_steps` | `BETWEEN_STEPS` | scans with a continuous extension (`scan_saving`) |
| anything else: adaptive steps, a step-size controller, an event, a diffrax adjoint, a progress meter, traced times, a saving the scans do not cover | `DIFFRAX` | `diffrax.diffeqsolve` (`diffeqsolve_run`) |

The first three are "plain fixed-step runs" (`RunPlan.plain_fixed_steps`): fixed
steps over Python-number times with the default adjoint (or `ReversibleAdjoint`)
and nothing that needs diffrax's loop. A new saving mode is a new `Saving` member,
its condition in `RunPlan.saving_mode` and its branch in `scan_run`.
"""

from __future__ import annotations

import enum
from typing import Any, NamedTuple

import diffrax
import jax
import numpy as np

from lagjax._core.static_values import Constant
from lagjax._integrate.fixed_step_loop import fixed_step_count, uniform_grid_saves
from lagjax._integrate.reversible_adjoint import ReversibleAdjoint
from lagjax._integrate.scan_saving import ScanSaving, scan_saving


class Saving(enum.Enum):
    """How a run saves its states, and so which loop runs it (module docstring)."""

    FINAL_STATE = "final state"
    STEP_GRID = "every k-th step"
    BETWEEN_STEPS = "between steps"
    DIFFRAX = "diffrax"

    @property
    def on_scan(self) -> bool:
        """Whether lagjax's own scans run it (else `diffrax.diffeqsolve`)."""
        return self is not Saving.DIFFRAX

    @property
    def on_step_grid(self) -> bool:
        """Whether it saves only states the steps reach (no interpolation)."""
        return self in (Saving.FINAL_STATE, Saving.STEP_GRID)


class RunPlan(NamedTuple):
    """How `simulate` was asked to integrate: times, tolerances, saving, adjoint."""

    t0: Any
    t1: Any
    dt: Any
    ts: Any
    rtol: float
    atol: float
    max_steps: int | None
    progress: bool
    saveat: diffrax.SaveAt | None
    adjoint: Any  # a diffrax adjoint, lj.ReversibleAdjoint (scans only), or None
    throw: bool
    dtype: Any
    dense: bool = False
    event: diffrax.Event | None = None
    controller: diffrax.AbstractStepSizeController | None = None
    progress_meter: diffrax.AbstractProgressMeter | None = None

    def saving_mode(self) -> Saving:
        """The run's `Saving`, hence its loop (the table of the module docstring)."""
        if not self.plain_fixed_steps():
            return Saving.DIFFRAX
        if self.saves_on_grid():
            return Saving.FINAL_STATE if self.ts is None else Saving.STEP_GRID
        if self.saving() is not None:
            return Saving.BETWEEN_STEPS
        return Saving.DIFFRAX

    def plain_fixed_steps(self) -> bool:
        """Fixed steps over Python-number times, the default (or reversible)
        adjoint, and no progress meter, step-size controller or event."""
        return (
            self.dt is not None
            and (self.adjoint is None or isinstance(self.adjoint, ReversibleAdjoint))
            and not self.progress
            and self.event is None
            and self.controller is None
            and self.progress_meter is None
            and all(isinstance(x, (int, float)) for x in (self.t0, self.t1, self.dt))
        )

    def saves_on_grid(self) -> bool:
        """Only the final state, or `ts` on a uniform subgrid of the steps."""
        plain = self.saveat is None and self.max_steps is None and not self.dense
        return plain and (self.ts is None or self.save_grid() is not None)

    def saving(self) -> ScanSaving | None:
        """The scans' saving between steps (`scan_saving`), or None."""
        return scan_saving(self.t0, self.t1, self.dt, self.ts, self.saveat,
                           self.dense, self.max_steps, self.dtype)  # fmt: skip

    def save_grid(self) -> tuple[int, int, int] | None:
        """`(lead, every, saves)` of `ts` on the step grid within [t0, t1], or None
        (traced `ts`, off the grid, or unevenly spaced)."""
        try:
            ts = np.asarray(self.ts, dtype=float)
        except jax.errors.TracerArrayConversionError:
            return None
        grid = uniform_grid_saves(self.t0, self.dt, ts)
        if grid is None:
            return None
        lead, every, saves = grid
        if lead + every * (saves - 1) > fixed_step_count(self.t0, self.t1, self.dt):
            return None
        return grid

    def for_compiled_call(self, mode: Saving) -> RunPlan:
        """The plan as the compiled call takes it: the scans lay out their loops in
        Python from the save times, so those travel as static constants
        (`lagjax._core.static_values`)."""
        if not mode.on_scan:
            return self
        # Concrete even when simulate is traced (inside a user's jit, device_put is
        # staged like any operation).
        with jax.ensure_compile_time_eval():
            ts = None if self.ts is None else jax.device_put(self.ts)
        return self._replace(ts=Constant(ts), saveat=Constant(self.saveat))
