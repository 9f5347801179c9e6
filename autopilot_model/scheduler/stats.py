"""Execution statistics of the main loop per task group (seed 002 Sec. 5, Table 2, Figs. 6-9).

The main loop records, for every call of a task group (the ``events`` pseudo group, the seven task
groups, and the physics as ``world``), the wall-clock ``perf_counter_ns`` before and after the call
into a per-group buffer (two ``list.append`` per call, nothing else). Every 1000 main-loop iterations
(and whenever a report is asked for) the buffers are cut into windows of ``window_calls`` calls
(1000 as in the paper), each giving:

* duty time average / min / max (us) of its calls (Figs. 6-9: one data point per 1000 calls);
* call frequency (Hz, wall clock) = ``(calls - 1) / (start of last call - start of first call)``.

The group's frequency is the mean of its window frequencies and its std the (population) standard
deviation over windows (Table 2). Without a complete window the frequency comes from the calls so far
and the std is not available. In lockstep mode (``speedup=0``) wall frequencies measure throughput;
``sim_hz`` (calls per simulated second) checks the prescalers.

An *overrun* is an iteration whose autopilot work (events + task groups, from the first timestamp of
the iteration to the last, excluding the world and the pacing sleep) took longer than the main loop
period of wall time; the worst iteration is kept as well.
"""

from __future__ import annotations

import math
import operator
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .spec import EVENTS_GROUP, TASK_GROUPS

WORLD = "world"
#: Rows of the statistics, in table order.
STAT_GROUPS: tuple[str, ...] = (EVENTS_GROUP, *TASK_GROUPS, WORLD)
WINDOW_CALLS = 1000


@dataclass(frozen=True)
class DutyWindow:
    """Statistics of one window of ``calls`` consecutive calls of a group."""

    calls: int
    freq_hz: float
    avg_us: float
    min_us: float
    max_us: float
    end_wall_s: float     # wall time of the window's last call, seconds since the stats started


class GroupStats:
    """Running aggregates and closed windows of one group."""

    __slots__ = ("buf", "calls", "freq_n", "freq_sq", "freq_sum", "max_ns", "min_ns", "name", "total_ns",
                 "windows")

    def __init__(self, name: str, max_windows: int) -> None:
        self.name = name
        self.buf: list[int] = []          # t0, t1, t0, t1, ... (perf_counter_ns) of pending calls
        self.windows: deque[DutyWindow] = deque(maxlen=max_windows)
        self.calls = 0                    # calls in closed windows
        self.total_ns = 0
        self.min_ns = math.inf
        self.max_ns = 0
        self.freq_n = 0
        self.freq_sum = 0.0
        self.freq_sq = 0.0

    def reset(self) -> None:
        self.buf.clear()                  # in place: the main loop holds buf.append
        self.windows.clear()
        self.calls = self.total_ns = self.max_ns = self.freq_n = 0
        self.min_ns = math.inf
        self.freq_sum = self.freq_sq = 0.0


class SchedulerStats:
    """Per-group call frequency and duty time, overruns and the worst iteration of a main loop."""

    def __init__(self, main_loop_hz: float, *, window_calls: int = WINDOW_CALLS, max_windows: int = 100_000,
                 iterations: Callable[[], int] | None = None) -> None:
        if window_calls < 2:
            raise ValueError("window_calls must be >= 2")
        self.main_loop_hz = float(main_loop_hz)
        self.period_ns = round(1e9 / self.main_loop_hz)
        self.window_calls = window_calls
        self.groups: dict[str, GroupStats] = {g: GroupStats(g, max_windows) for g in STAT_GROUPS}
        self._iterations = iterations or (lambda: 0)
        self.timed = True
        """False when the main loop runs untimed (:meth:`~.mainloop.MainLoop.set_timed`): nothing here is
        measured, and :meth:`as_dict` and :meth:`table` say so."""
        self.reset()

    # --- recording (called by the main loop) -------------------------------------------------------
    def appender(self, group: str) -> Callable[[int], None]:
        """``append`` of the group's buffer: the main loop calls it with t0 then t1 of each call."""
        return self.groups[group].buf.append

    def reset(self) -> None:
        for g in self.groups.values():
            g.reset()
        self.overruns = 0
        self.worst_ns = 0
        self.worst_iteration = -1
        self.worst_sim_us = 0
        self.wall_start_ns = time.perf_counter_ns()
        self.wall_end_ns = self.wall_start_ns
        self.iterations_at_reset = self._iterations()

    def record_overrun(self, duration_ns: int) -> None:
        self.overruns += 1

    def record_worst(self, duration_ns: int, iteration: int, sim_us: int) -> None:
        self.worst_ns = duration_ns
        self.worst_iteration = iteration
        self.worst_sim_us = sim_us

    def flush(self) -> None:
        """Close every complete window of every group."""
        w2 = 2 * self.window_calls
        for g in self.groups.values():
            while len(g.buf) >= w2:
                chunk = g.buf[:w2]
                del g.buf[:w2]
                self._close(g, chunk)

    def _close(self, g: GroupStats, chunk: list[int]) -> None:
        a = np.array(chunk, dtype=np.int64).reshape(-1, 2)
        starts, ends = a[:, 0], a[:, 1]
        d = ends - starts
        n, total, lo, hi = len(d), int(d.sum()), int(d.min()), int(d.max())
        span = int(starts[-1] - starts[0])
        freq = (n - 1) * 1e9 / span if span > 0 else math.nan
        g.windows.append(DutyWindow(n, freq, total / n / 1e3, lo / 1e3, hi / 1e3,
                                    (int(ends[-1]) - self.wall_start_ns) / 1e9))
        g.calls += n
        g.total_ns += total
        g.min_ns = min(g.min_ns, lo)
        g.max_ns = max(g.max_ns, hi)
        if not math.isnan(freq):
            g.freq_n += 1
            g.freq_sum += freq
            g.freq_sq += freq * freq

    # --- reporting ------------------------------------------------------------------------------
    def windows(self, group: str) -> list[DutyWindow]:
        """The closed windows of ``group`` (oldest first; at most ``max_windows`` kept)."""
        self.flush()
        return list(self.groups[group].windows)

    def group_summary(self, group: str) -> dict[str, Any]:
        """calls, sim_hz, freq_hz, freq_std_hz, avg_us, min_us, max_us, windows of one group."""
        self.flush()
        g = self.groups[group]
        calls, total, lo, hi = g.calls, g.total_ns, g.min_ns, g.max_ns
        pending = len(g.buf) // 2
        if pending:
            starts, ends = g.buf[0:2 * pending:2], g.buf[1:2 * pending:2]
            d = list(map(operator.sub, ends, starts))
            calls += pending
            total += sum(d)
            lo, hi = min(lo, min(d)), max(hi, max(d))
        if g.freq_n:
            freq = g.freq_sum / g.freq_n
            std = math.sqrt(max(0.0, g.freq_sq / g.freq_n - freq * freq)) if g.freq_n > 1 else math.nan
        elif pending > 1 and g.buf[2 * pending - 2] > g.buf[0]:
            freq, std = (pending - 1) * 1e9 / (g.buf[2 * pending - 2] - g.buf[0]), math.nan
        else:
            freq, std = math.nan, math.nan
        sim_s = self.iterations() / self.main_loop_hz
        return {
            "calls": calls,
            "sim_hz": calls / sim_s if sim_s > 0 else math.nan,
            "freq_hz": freq,
            "freq_std_hz": std,
            "avg_us": total / calls / 1e3 if calls else math.nan,
            "min_us": lo / 1e3 if calls else math.nan,
            "max_us": hi / 1e3 if calls else math.nan,
            "windows": len(g.windows),
        }

    def iterations(self) -> int:
        """Main-loop iterations since the last reset."""
        return self._iterations() - self.iterations_at_reset

    def as_dict(self, include_windows: bool = False) -> dict[str, Any]:
        """All statistics as plain data (NaN where not available)."""
        n = self.iterations()
        sim_s = n / self.main_loop_hz
        wall_s = (self.wall_end_ns - self.wall_start_ns) / 1e9
        out: dict[str, Any] = {
            "main_loop_hz": self.main_loop_hz,
            "window_calls": self.window_calls,
            "iterations": n,
            "sim_time_s": sim_s,
            "wall_time_s": wall_s,
            "realtime_factor": sim_s / wall_s if wall_s > 0 else math.nan,
            "overruns": self.overruns,
            "worst_iteration": {"iteration": self.worst_iteration, "sim_time_s": self.worst_sim_us / 1e6,
                                "duration_us": self.worst_ns / 1e3},
            "groups": {g: self.group_summary(g) for g in STAT_GROUPS},
            "timed": self.timed,
        }
        if include_windows:
            for g in STAT_GROUPS:
                out["groups"][g]["window_list"] = [asdict(w) for w in self.groups[g].windows]
        return out

    def table(self) -> str:
        """Printable text table (Table 2 plus duty time), one row per group, then the loop summary."""
        d = self.as_dict()
        if not self.timed:
            return (f"iterations {d['iterations']} ({d['sim_time_s']:.3f} s simulated); not timed (a fleet's "
                    "vehicle, or a model run without --stats: MainLoop.set_timed)")
        head = (f"{'group':<11} {'calls':>9} {'sim Hz':>9} {'wall Hz':>11} {'std Hz':>9} "
                f"{'avg us':>8} {'min us':>8} {'max us':>9} {'windows':>7}")
        lines = [head, "-" * len(head)]
        for g, s in d["groups"].items():
            if g == WORLD:
                lines.append("-" * len(head))
            lines.append(f"{g:<11} {s['calls']:>9d} {_f(s['sim_hz'], 9, 3)} {_f(s['freq_hz'], 11, 3)} "
                         f"{_f(s['freq_std_hz'], 9, 3)} {_f(s['avg_us'], 8, 1)} {_f(s['min_us'], 8, 1)} "
                         f"{_f(s['max_us'], 9, 1)} {s['windows']:>7d}")
        w = d["worst_iteration"]
        lines.append("-" * len(head))
        lines.append(f"iterations {d['iterations']} ({d['sim_time_s']:.3f} s simulated, "
                     f"{d['wall_time_s']:.3f} s wall, x{d['realtime_factor']:.1f} real time); "
                     f"windows of {self.window_calls} calls")
        lines.append(f"overruns (autopilot work > {self.period_ns / 1e3:g} us): {d['overruns']}; worst "
                     f"iteration #{w['iteration']} at t={w['sim_time_s']:.3f} s: {w['duration_us']:.1f} us")
        return "\n".join(lines)


def _f(x: float, width: int, digits: int) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return f"{'-':>{width}}"
    return f"{x:>{width}.{digits}f}"
