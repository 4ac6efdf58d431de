r"""Runs of a heyoka integrator over a block of members: saves, events, outcomes.

One `HeyokaRunner` holds what a run is compiled for — the translated system
(`heyoka_expressions`), its terminal events, the tolerance ε and the precision —
and runs any number of members $(y_0, \text{pars}, t_0, t_1, t_s)$ at once:
one member on heyoka's scalar integrator, more on its batch mode in blocks of
the SIMD width (each lane with its own times and steps; the last block padded
with copies of its final member). Everything is NumPy in, NumPy out, so the
same runner serves a direct call and a `jax.pure_callback`
(`heyoka_callback`).

**Saves** come from heyoka's dense output: `propagate_grid` evaluates each
step's Taylor polynomial $\sum_k y_k\,(t - t_n)^k$ at the save times it covers,
with no extra evaluation of $f$. A run that saves only its final state, with
no events, is driven as heyoka's own users drive it — one `propagate_until` per
block of lanes, the bookkeeping outside the loop over blocks (`_to_ends`), or
for one member `HeyokaRunner.final_state` — so the Python around heyoka costs
a few per cent of its run, not a third (1024 double pendulums to t = 10).

**Events.** A condition $g(t, y)$ translated into an expression becomes a
terminal `heyoka.t_event`: heyoka finds the roots of the step polynomial of
$g$ (the composition is Taylor-expanded with the state) in every step and stops
the run at the first one, propagating the state exactly to it (Biscani & Izzo
2021, §5). A run an event ended keeps the saves before it; with only the final
state asked for, the saved row is the state at the event.

**Outcomes** are small integers (a `pure_callback` cannot raise): `SUCCESS`,
`STEP_LIMIT`, `NON_FINITE`, `BAD_TIMES` (save times not ordered from $t_0$ to
$t_1$), `OTHER`, and `FIRST_EVENT + i` when event $i$ ended the run.

References: F. Biscani & D. Izzo, "Revisiting high-order Taylor methods for
astrodynamics and celestial mechanics", MNRAS 504 (2021) 2614; the heyoka
documentation, "Event detection" and "Batch mode".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from lagjax.taylor.heyoka_cache import heyoka_integrator
from lagjax.taylor.heyoka_expressions import HeyokaSystem, import_heyoka

SUCCESS, STEP_LIMIT, NON_FINITE, BAD_TIMES, OTHER, FIRST_EVENT = range(6)
OUTCOME_NAMES = {
    SUCCESS: "time_limit",
    STEP_LIMIT: "step_limit",
    NON_FINITE: "err_nf_state",
    BAD_TIMES: "bad_times",
    OTHER: "other",
}


def outcome_name(code: Any) -> str:
    """heyoka's name of an outcome code (`event_i` for event i)."""
    code = int(code)
    return OUTCOME_NAMES.get(code, f"event_{code - FIRST_EVENT}")


@dataclass(frozen=True)
class HeyokaEvent:
    """A terminal event: the run stops where `expression` crosses zero in
    `direction` (0 either way, +1 upward, -1 downward)."""

    expression: Any
    direction: int = 0


class Rows(NamedTuple):
    """Members' saves: `ts` (B, T), `ys` (B, T, n), `num_steps` (B,), `codes` (B,)."""

    ts: np.ndarray
    ys: np.ndarray
    num_steps: np.ndarray
    codes: np.ndarray


@dataclass(frozen=True)
class HeyokaRunner:
    """A compiled run configuration (see the module docstring). `final_only`:
    the run saves only where it ended (t1, or the event), not at given times."""

    system: HeyokaSystem
    tol: float
    max_steps: int
    events: tuple[HeyokaEvent, ...] = ()
    final_only: bool = True
    fp_type: Any = np.float64
    compact_mode: bool | None = None
    batch_size: int | None = None  # lanes per block; default heyoka's SIMD width

    def __call__(self, y0s, pars, t0s, t1s, ts) -> Rows:
        """Run every member: `y0s` (B, n), `pars` (B, P), `t0s`, `t1s` (B,),
        `ts` (B, T) the save times (for `final_only`, `ts[:, -1]` is t1)."""
        y0s, pars = (np.asarray(x, dtype=self.fp_type) for x in (y0s, pars))
        t0s, t1s, ts = (np.asarray(x, dtype=self.fp_type) for x in (t0s, t1s, ts))
        bad = ~_ordered(t0s, t1s, ts)
        out = Rows(
            np.where(bad[:, None], np.nan, ts),
            np.full((*ts.shape, y0s.shape[1]), np.nan, dtype=self.fp_type),
            np.zeros(ts.shape[0], np.int64),
            np.where(bad, BAD_TIMES, SUCCESS).astype(np.int32),
        )
        good = np.flatnonzero(~bad)
        width = self.batch_size or import_heyoka().recommended_simd_size(
            fp_type=self.fp_type
        )
        width = 1 if good.size == 1 else width
        ta = heyoka_integrator(
            self.system, self.tol, width, self.fp_type, self.compact_mode, self.events
        )
        lanes = _Lanes(ta, width, self.max_steps)
        if self.final_only and not self.events and good.size:
            _to_ends(lanes, good, y0s, pars, t0s, t1s, out)
            return out
        for start in range(0, good.size, width):
            live = good[start : start + width]
            chunk = np.concatenate([live, np.repeat(live[-1:], width - live.size)])
            block = self._block(lanes, y0s[chunk], pars[chunk], t0s[chunk],
                                t1s[chunk], ts[chunk])  # fmt: skip
            for field, value in zip(out, block):
                field[live] = value[: live.size]
        return out

    def integrator(self) -> Any:
        """The compiled scalar integrator `final_state` runs on (cached,
        `heyoka_cache.heyoka_integrator`)."""
        return heyoka_integrator(
            self.system, self.tol, 1, self.fp_type, self.compact_mode, self.events
        )

    def final_state(self, ta: Any, y0, pars, t0: float, t1: float) -> Rows:
        """One member to `t1`, saved there, on the scalar integrator `ta` (from
        `integrator()`): the rows `__call__` gives for it without a batch axis,
        from one `propagate_until`, as heyoka's own users call it — no blocks,
        lanes or dense-output grid, whose NumPy bookkeeping costs as much as a
        short run. Only for a `final_only` runner without events."""
        if self.events or not self.final_only:
            raise ValueError("final_state runs to t1 without events; use the call")
        state = ta.state  # a view of heyoka's state: one pybind11 call, not two
        ta.time = self.fp_type(t0)
        state[:] = y0
        if len(pars):
            ta.pars[:] = used_pars(pars, len(ta.pars))
        outcome, _, _, steps, *_ = ta.propagate_until(
            self.fp_type(t1), max_steps=self.max_steps
        )
        code = _code(outcome)
        state = state.copy() if code == SUCCESS else np.full_like(state, np.nan)
        return Rows(
            np.array((t1,), self.fp_type),  # one C call (np.full's is Python)
            state[None],
            np.asarray(steps, np.int64),
            np.asarray(code, np.int32),
        )

    def one_to_end(self, y0, pars, t0, t1, ts) -> Rows | None:
        """One member without a batch axis — `y0` (n,), `pars` (P,), `t0`, `t1`,
        `ts` (1,) holding t1 — to `t1` by `final_state`: the rows `__call__`
        gives for it, without the batch bookkeeping (its time-order check,
        lanes and outcome arrays cost 0.1–0.2 ms a call, a twentieth of a 3 ms
        run). None for a runner with events or saves at given times."""
        if self.events or not self.final_only:
            return None
        fp = self.fp_type
        start, end, saves = fp(t0), fp(t1), np.asarray(ts, fp)
        sign = 1 if end >= start else -1
        ordered = saves.shape == (1,)  # NaN times compare False: refused
        ordered = ordered and (saves[0] - start) * sign >= 0
        if not (ordered and (end - saves[-1]) * sign >= 0):
            return Rows(
                np.full(saves.shape, np.nan, fp),
                np.full((*saves.shape, np.shape(y0)[0]), np.nan, fp),
                np.asarray(0, np.int64),
                np.asarray(BAD_TIMES, np.int32),
            )  # `_ordered` refused them (NaN times among them)
        return self.final_state(self.integrator(), y0, pars, start, end)

    def _block(self, lanes: _Lanes, y0s, pars, t0s, t1s, grids) -> Rows:
        """One block of members through heyoka, one per lane."""
        lanes.start(y0s, pars, t0s)
        if self.events:
            lanes.watch_from(t0s)
        # heyoka's batch mode stops every lane at any lane's terminal event
        run = self._stepwise if lanes.batch and self.events else self._on_grid
        codes, steps, ys, (end_times, end_states) = run(lanes, grids)
        saved, ys = self._event_rows(codes, grids.copy(), ys, end_times, end_states,
                                     t0s, t1s)  # fmt: skip
        return Rows(saved, ys, steps, codes)

    @staticmethod
    def _on_grid(lanes: _Lanes, grids):
        """To the first save time, then heyoka's dense output over the grid."""
        codes, steps = lanes.until(grids[:, 0])
        stopped, ends = codes != SUCCESS, lanes.read()
        lanes.restart(stopped, grids[:, 0])  # heyoka's grid starts where it is
        more_codes, more_steps, states = lanes.grid(grids)
        codes = np.where(stopped, codes, more_codes)
        steps = steps + np.where(stopped, 0, more_steps)
        end_times, end_states = lanes.read()
        end_times = np.where(stopped, ends[0], end_times)
        end_states = np.where(stopped[:, None], ends[1], end_states)
        ys = np.where(stopped[:, None, None], np.nan, states)
        return codes, steps, ys, (end_times, end_states)

    @staticmethod
    def _stepwise(lanes: _Lanes, grids):
        """To each save time in turn, every lane on to its own time or event."""
        width, count = grids.shape
        ys = np.full((width, count, lanes.ta.state.shape[0]), np.nan)
        codes, steps = np.full(width, SUCCESS, np.int32), np.zeros(width, np.int64)
        running = np.ones(width, bool)
        for k in range(count):
            reached, more = lanes.until_each(grids[:, k], running)
            steps += more
            codes = np.where(running & (reached != SUCCESS), reached, codes)
            running &= reached == SUCCESS
            ys[running, k] = lanes.read()[1][running]
        return codes, steps, ys, lanes.read()

    def _event_rows(self, codes, saved, ys, end_times, end_states, t0s, t1s):
        """Where an event ended a run: the final row at the event (`final_only`),
        or the saves after it marked t = inf, y = inf (as diffrax marks them)."""
        event = codes >= FIRST_EVENT
        if self.final_only:
            saved[event, -1], ys[event, -1] = end_times[event], end_states[event]
            return saved, ys
        after = (saved - end_times[:, None]) * _sign(t0s, t1s)[:, None] > 0
        after &= event[:, None]
        return np.where(after, np.inf, saved), np.where(after[..., None], np.inf, ys)


def _to_ends(lanes: _Lanes, good, y0s, pars, t0s, t1s, out: Rows) -> None:
    """Every `good` member straight to its t1 (`final_only`, no events), one
    `propagate_until` per block of lanes, the rows written into `out`: what
    `HeyokaRunner._block` gives there, with its dense-output grid left out and
    the NumPy bookkeeping moved out of the loop over blocks — in the loop it
    cost a third of heyoka's own time for 1024 double pendulums to t = 10 at
    tol 1e-9."""
    width = lanes.width
    members = np.concatenate([good, np.repeat(good[-1:], -good.size % width)])
    y0s, pars, t0s, t1s = (x[members] for x in (y0s, pars, t0s, t1s))
    states, results = np.empty_like(y0s), []
    for start in range(0, members.size, width):
        block = slice(start, start + width)
        lanes.start(y0s[block], pars[block], t0s[block])
        results += lanes.propagate_until(t1s[block])
        states[block] = lanes.states()
    codes, steps = _Lanes.codes_and_steps(results[: good.size])
    reached = (codes == SUCCESS)[:, None]
    out.ys[good, -1] = np.where(reached, states[: good.size], np.nan)
    out.num_steps[good], out.codes[good] = steps, codes


def _sign(t0s: np.ndarray, t1s: np.ndarray) -> np.ndarray:
    return np.where(t1s >= t0s, 1.0, -1.0)


def _ordered(t0s, t1s, grids) -> np.ndarray:
    """Per member: the save times strictly ordered from t0 to t1 (heyoka's grid
    must be strictly monotonic)."""
    sign = _sign(t0s, t1s)[:, None]
    steps = np.diff(grids, axis=1) * sign
    first = (grids[:, 0] - t0s) * sign[:, 0]
    last = (t1s - grids[:, -1]) * sign[:, 0]
    return np.all(steps > 0, axis=1) & (first >= 0) & (last >= 0)


_CODES = {name: code for code, name in OUTCOME_NAMES.items()}


_CODE_OF: dict[Any, int] = {}  # outcomes seen (a lookup: reading one costs µs)


def _code(outcome: Any) -> int:
    """heyoka's `taylor_outcome` as an outcome code."""
    code = _CODE_OF.get(outcome)
    if code is None:
        code = _CODE_OF[outcome] = _new_code(outcome)
    return code


def _new_code(outcome: Any) -> int:
    value = int(outcome.value)
    if value < 0 and value >= -(2**31):  # a terminal event: -1 - its index
        return FIRST_EVENT - 1 - value
    return _CODES.get(outcome.name, OTHER)


def used_pars(pars: np.ndarray, count: int) -> np.ndarray:
    """The values of heyoka's `count` parameters from lagjax's `pars` (every
    scalar of args, `heyoka.par[i]` on the first axis). heyoka counts the
    parameters of a system as the highest index its equations use, plus one: a
    parameter the equations never read (a scene's initial amplitude) is not
    counted when it is the last, and heyoka refuses more values than it counts."""
    return pars[:count]


class _Lanes:
    """heyoka's scalar and batch integrators behind one interface of (W, …)
    NumPy arrays."""

    def __init__(self, ta: Any, width: int, max_steps: int) -> None:
        self.ta, self.width, self.batch = ta, width, width > 1
        self.max_steps = max_steps

    def start(self, y0s, pars, t0s) -> None:
        used = used_pars(pars.T, len(self.ta.pars))
        if self.batch:
            self.ta.set_time(t0s)
            self.ta.state[:], self.ta.pars[:] = y0s.T, used
        else:
            self.ta.time = t0s[0]
            self.ta.state[:], self.ta.pars[:] = y0s[0], used[:, 0]

    def watch_from(self, t0s) -> None:
        """The events' callbacks told the lanes' start times (a condition zero
        at t0 ends no run)."""
        for event in self.ta.t_events:
            event.callback.starts = t0s

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """(times (W,), states (W, n)) where the lanes are now."""
        if self.batch:
            return np.array(self.ta.time), np.array(self.ta.state.T)
        return np.array([self.ta.time]), np.array(self.ta.state)[None]

    def restart(self, lanes: np.ndarray, times: np.ndarray) -> None:
        """Move the time of stopped `lanes` to `times` (their later results are
        discarded), so a batch grid call accepts every lane."""
        if lanes.any():
            now = self.read()[0]
            new = np.where(lanes, times, now)
            if self.batch:
                self.ta.set_time(new)
            else:
                self.ta.time = new[0]

    def states(self) -> np.ndarray:
        """The lanes' states (W, n), a view into the integrator."""
        return self.ta.state.T if self.batch else self.ta.state[None]

    def propagate_until(self, times: np.ndarray) -> list:
        """heyoka's result tuple of each lane, on to `times`."""
        if self.batch:
            self.ta.propagate_until(times, max_steps=self.max_steps)
            return list(self.ta.propagate_res)
        return [self.ta.propagate_until(times[0], max_steps=self.max_steps)]

    def until(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.codes_and_steps(self.propagate_until(times))

    def until_each(self, times: np.ndarray, active: np.ndarray):
        """Batch lanes on to `times` (the inactive ones stay), continued while
        another lane's terminal event interrupts them: codes, steps."""
        codes, steps = (
            np.full(active.shape, SUCCESS, np.int32),
            np.zeros(active.shape, np.int64),
        )
        active = active.copy()
        while active.any():
            goal = np.where(active, times, self.read()[0])
            budget = max(self.max_steps - int(steps[active].max()), 1)
            self.ta.propagate_until(goal, max_steps=budget)
            results = self.ta.propagate_res
            # "success" (or a continued event, value >= 0): another lane's
            # event stopped this one on its way
            interrupted = np.array(
                [r[0].name == "success" or int(r[0].value) >= 0 for r in results]
            )
            more_codes, more_steps = self.codes_and_steps(results)
            steps += np.where(active, more_steps, 0)
            done = active & ~interrupted
            codes[done] = more_codes[done]
            active &= interrupted
        return codes, steps

    def grid(self, grids: np.ndarray):
        """Codes, steps and states (W, T, n) over each lane's grid."""
        if self.batch:
            _, states = self.ta.propagate_grid(
                np.ascontiguousarray(grids.T), max_steps=self.max_steps
            )
            codes, steps = self.codes_and_steps(self.ta.propagate_res)
            return codes, steps, np.transpose(states, (2, 0, 1))
        result = self.ta.propagate_grid(grids[0], max_steps=self.max_steps)
        codes, steps = self.codes_and_steps([result])
        states = np.full((1, grids.shape[1], self.ta.state.shape[0]), np.nan)
        states[0, : result[-1].shape[0]] = result[-1]
        return codes, steps, states

    @staticmethod
    def codes_and_steps(results) -> tuple[np.ndarray, np.ndarray]:
        """Outcome codes and step counts of heyoka's result tuples."""
        codes = np.array([_code(r[0]) for r in results], np.int32)
        return codes, np.array([r[3] for r in results], np.int64)
