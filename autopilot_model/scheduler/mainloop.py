"""The fixed-frequency main loop: a non-preemptive static scheduler (seed 002 Sec. 4.2, Fig. 4).

One iteration (:meth:`MainLoop.step`):

1. poll every event function (datalink etc.), every iteration;
2. call the periodic functions due in this iteration (``iteration % prescaler == offset``), task group
   by task group in the order ``sensors, estimation, navigation, control, actuators, core, telemetry``,
   modules in topological order;
3. step the world (physics) one period if a ``world_step`` is given (timed as ``world``);
4. advance the simulated clock by one period and, in real-time mode (``clock.speedup > 0``), pace.

For speed the call lists of every phase of the hyperperiod are precomputed (identical phases share one
tuple), so ``step`` does no lookup and no allocation beyond the timing stamps: each group that has
calls is timed with ``perf_counter_ns`` before and after (consecutive groups share the stamp between
them, so a group's duty includes ~50 ns of the previous group's bookkeeping), stamps appended to the
group's statistics buffer (:mod:`.stats`). Measured overhead on the development VM (where one
``perf_counter_ns`` costs ~100 ns): 2.5-3.5 us per iteration with events, seven groups and the world.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from time import perf_counter_ns
from typing import Any, Protocol

from .errors import SchedulerError
from .schedule import Registry, Schedule
from .spec import EVENTS_GROUP, TASK_GROUPS
from .stats import WINDOW_CALLS, WORLD, SchedulerStats

log = logging.getLogger(__name__)

_Phase = tuple[tuple[Callable[[int], None], tuple[Callable[[], Any], ...]], ...]

FLUSH_EVERY = 1000   # iterations between two statistics flushes


class LoopClock(Protocol):
    """What the main loop needs of its clock (:class:`taskflight_common.clock.SimClock`)."""

    speedup: float
    now_us: int

    def advance(self, dt_us: int) -> None: ...

    def pace(self) -> float: ...


class MainLoop:
    """Runs a bound :class:`~.schedule.Schedule` at the main loop frequency on a simulated clock."""

    def __init__(self, schedule: Schedule, clock: LoopClock, world_step: Callable[[], Any] | None = None,
                 *, registry: Registry | None = None, window_calls: int = WINDOW_CALLS) -> None:
        if registry is not None:
            schedule = schedule.bind(registry)
        if not schedule.bound:
            raise SchedulerError("the schedule's functions are not bound: pass registry= or use "
                                 "build_schedule(config, registry) / schedule.bind(registry)")
        self.schedule = schedule
        self.clock = clock
        self.world_step = world_step
        self.period_us = schedule.period_us
        self._period_ns = schedule.period_us * 1000
        self._n = 0
        self._phase = 0
        self._hyper = schedule.hyperperiod
        self.stats = SchedulerStats(schedule.main_loop_hz, window_calls=window_calls,
                                    iterations=lambda: self._n)
        self._events: tuple[Callable[[], Any], ...] = tuple(e.fn for e in schedule.events)  # type: ignore[misc]
        self._ev_append = self.stats.appender(EVENTS_GROUP)
        self._world_append = self.stats.appender(WORLD)
        self._phases = self._build_phases()
        self._next_flush = FLUSH_EVERY
        self._initialised = False

    def set_timed(self, timed: bool) -> None:
        """Time every group of every iteration (the default) or none.

        Untimed, :meth:`step` runs the same calls in the same order with no timing stamps, no statistics
        and no overrun check (about a quarter of a vehicle's iteration: ~5 of ~20 us, measured on the
        development VM with ten fleet vehicles in lockstep). A fleet (:mod:`autopilot_model.fleet`) runs its
        vehicles untimed: they share one period, whose lateness the fleet measures itself, so a vehicle's
        own overruns would say nothing. :attr:`stats` then says it measured nothing
        (:attr:`SchedulerStats.timed`)."""
        self.stats.timed = timed
        if timed:
            self.__dict__.pop("step", None)
        else:
            self.step = self._step_untimed  # type: ignore[method-assign]

    @property
    def iteration(self) -> int:
        """Number of iterations completed (the index of the next one)."""
        return self._n

    def _build_phases(self) -> tuple[_Phase, ...]:
        h = self._hyper
        periodic = self.schedule.periodic
        members: list[list[int]] = [[] for _ in range(h)]
        for i, p in enumerate(periodic):          # schedule order = group order, then topological
            for ph in range(p.offset, h, p.prescaler):
                members[ph].append(i)
        appenders = {g: self.stats.appender(g) for g in TASK_GROUPS}
        cache: dict[tuple[int, ...], tuple[Any, ...]] = {}
        phases = []
        for ids in members:
            key = tuple(ids)
            entry = cache.get(key)
            if entry is None:
                groups: list[tuple[Callable[[int], None], tuple[Callable[[], Any], ...]]] = []
                for g in TASK_GROUPS:
                    fns = tuple(periodic[i].fn for i in ids if periodic[i].group == g)
                    if fns:
                        groups.append((appenders[g], fns))  # type: ignore[arg-type]
                entry = cache[key] = tuple(groups)
            phases.append(entry)
        log.debug("main loop: %d phases, %d distinct call lists", h, len(cache))
        return tuple(phases)

    def run_init(self) -> None:
        """Call the init functions (topological order) and start the statistics."""
        for f in self.schedule.init:
            f.fn()  # type: ignore[misc]
        self._initialised = True
        self.stats.reset()

    def step(self) -> None:
        """One main loop iteration (see the module docstring)."""
        pc = perf_counter_ns
        p = self._phase
        groups = self._phases[p]
        p += 1
        self._phase = 0 if p == self._hyper else p
        try:
            # One stamp between two consecutive groups: the stamp after a group is the one before the
            # next (its two appends, ~50 ns, count in the next group's duty).
            t_start = t = pc()
            events = self._events
            if events:
                for f in events:
                    f()
                t1 = pc()
                ap = self._ev_append
                ap(t)
                ap(t1)
                t = t1
            for ap, fns in groups:
                for f in fns:
                    f()
                t1 = pc()
                ap(t)
                ap(t1)
                t = t1
            d = t - t_start
            world = self.world_step
            if world is not None:
                world()
                t1 = pc()
                ap = self._world_append
                ap(t)
                ap(t1)
                t = t1
            st = self.stats
            if d > self._period_ns:
                st.record_overrun(d)
            if d > st.worst_ns:
                st.record_worst(d, self._n, self.clock.now_us)
            st.wall_end_ns = t
            clock = self.clock
            clock.advance(self.period_us)
            n = self._n = self._n + 1
            if n >= self._next_flush:          # before pacing: the sleep absorbs it in real time
                self._next_flush = n + FLUSH_EVERY
                st.flush()
            if clock.speedup > 0:
                clock.pace()
        except BaseException as exc:
            exc.add_note(f"in main loop iteration {self._n} (t={self.clock.now_us / 1e6:.6f} s)")
            raise

    def _step_untimed(self) -> None:
        """:meth:`step` without the timing (:meth:`set_timed`)."""
        p = self._phase
        groups = self._phases[p]
        p += 1
        self._phase = 0 if p == self._hyper else p
        try:
            for f in self._events:
                f()
            for _ap, fns in groups:
                for f in fns:
                    f()
            world = self.world_step
            if world is not None:
                world()
            clock = self.clock
            clock.advance(self.period_us)
            self._n += 1
            if clock.speedup > 0:
                clock.pace()
        except BaseException as exc:
            exc.add_note(f"in main loop iteration {self._n} (t={self.clock.now_us / 1e6:.6f} s)")
            raise

    def run(self, duration_s: float | None = None, stop_event: threading.Event | None = None) -> int:
        """Run ``duration_s`` of simulated time (None: forever) or until ``stop_event`` is set.

        Calls :meth:`run_init` first if it has not run. Returns the number of iterations done.
        ``stop_event`` is checked every 8 iterations.
        """
        if not self._initialised:
            self.run_init()
        step = self.step
        start = self._n
        if duration_s is not None:
            todo = round(duration_s * self.schedule.main_loop_hz)
            if stop_event is None:
                for _ in range(todo):
                    step()
            else:
                while self._n - start < todo:
                    if (self._n & 7) == 0 and stop_event.is_set():
                        break
                    step()
        else:
            while True:
                if (self._n & 7) == 0 and stop_event is not None and stop_event.is_set():
                    break
                step()
        return self._n - start
