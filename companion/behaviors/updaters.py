"""Belief updaters (seed 001 Sec. 6.2.5): processes that keep a category of beliefs current.

"Each belief updater is a process specialized in updating a category of beliefs and modifies the
content of the belief memory using the services provided by the belief manager." Updaters are
independent of each other and pluggable: anything with ``name``, ``period_s`` and
``update(memory, now_s)`` can be given to the :class:`BeliefUpdaterRunner`, which calls each at its
own (low) rate on the autopilot's clock.

The :class:`CommonBeliefUpdater` ("a special belief updater ... maintaining an updated number of basic
beliefs that are common for most robots, such as beliefs related to the position and battery
charge") derives from the node's :class:`~companion.node.VehicleStatus` (what the link mirrors):

==========================================  ===================================================
belief                                      source
==========================================  ===================================================
``object(self, aerial_robot)``              always
``position(self, (north, east, up))``       LOCAL_POSITION_NED (m from home, up = -z, 0.01 m)
``flight_state(self, X)``                   :func:`companion.node.flight_state` (armed, landed_state, mode)
``armed(self, yes|no)``                     HEARTBEAT base_mode
``mode(self, GUIDED)``                      HEARTBEAT custom_mode as the ArduCopter mode name
``object(1, battery)``                      always
``charge(1, full|high|medium|low|empty)``   SYS_STATUS battery_remaining (see :func:`charge_level`)
``battery_percentage(1, 87)``               SYS_STATUS battery_remaining
``home(self, (lat, lon, alt))``             HOME_POSITION (deg, deg, m AMSL)
``localization(self, healthy|unhealthy)``   a LOCAL_POSITION_NED within ``max_position_age_s``
==========================================  ===================================================

A fact that becomes unknown (no battery report, no mode yet) removes its belief rather than keep a
stale one; the position is kept when the estimate goes stale (``localization`` says so).
"""

from __future__ import annotations

import logging
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from companion.behaviors.beliefs import Belief, BeliefMemory, Term
from companion.node import VehicleStatus

log = logging.getLogger(__name__)

#: battery_remaining thresholds (percent, lower bound inclusive) -> charge value, checked in order.
CHARGE_LEVELS: tuple[tuple[int, str], ...] = (
    (90, "full"),
    (60, "high"),
    (30, "medium"),
    (10, "low"),
    (0, "empty"),
)


def charge_level(percent: int | float | None) -> str | None:
    """``full`` >= 90 %, ``high`` >= 60, ``medium`` >= 30, ``low`` >= 10, ``empty`` below 10;
    None when unknown (None or negative: MAVLink's -1)."""
    if percent is None or percent < 0:
        return None
    for bound, name in CHARGE_LEVELS:
        if percent >= bound:
            return name
    return "empty"


@runtime_checkable
class BeliefUpdaterLike(Protocol):
    """What the runner needs of an updater."""

    name: str
    period_s: float

    def update(self, memory: BeliefMemory, now_s: float) -> None: ...


class BeliefUpdater(ABC):
    """Base of the belief updaters: a name, a period (s of the autopilot's clock) and ``update``."""

    name: str = "updater"
    period_s: float = 1.0

    @abstractmethod
    def update(self, memory: BeliefMemory, now_s: float) -> None:
        """Revise this updater's beliefs at autopilot time ``now_s`` (seconds)."""


class CommonBeliefUpdater(BeliefUpdater):
    """The common belief updater (Sec. 6.2.5): position, flight state, battery, mode, home, localization.

    ``state`` returns the vehicle's current status (e.g. ``QuadNode.vehicle_status``); ``now``
    is the autopilot's clock in seconds, used when :meth:`update` is called without a time.
    """

    name = "common"

    def __init__(self, state: Callable[[], VehicleStatus], now: Callable[[], float] | None = None, *,
                 period_s: float = 0.5, max_position_age_s: float = 1.0, self_id: str = "self",
                 battery_id: int = 1) -> None:
        if period_s <= 0 or max_position_age_s <= 0:
            raise ValueError("period_s and max_position_age_s must be positive")
        self._state = state
        self._now = now
        self.period_s = period_s
        self.max_position_age_s = max_position_age_s
        self.self_id = self_id
        self.battery_id = battery_id

    def beliefs_for(self, s: VehicleStatus, now_s: float) -> tuple[list[Belief], list[tuple[str, Term]]]:
        """(beliefs to hold, (predicate, object) pairs to forget) for one vehicle status."""
        me, bat = self.self_id, self.battery_id
        hold = [Belief("object", (me, "aerial_robot")), Belief("object", (bat, "battery")),
                Belief("flight_state", (me, s.flight.value)),
                Belief("armed", (me, "yes" if s.armed else "no"))]
        forget: list[tuple[str, Term]] = []
        if s.position is not None:
            n, e, d = s.position
            hold.append(Belief("position", (me, (_r(n, 2), _r(e, 2), _r(-d, 2)))))
        fresh = (s.position_time_ms is not None
                 and abs(now_s - s.position_time_ms * 1e-3) <= self.max_position_age_s)
        hold.append(Belief("localization", (me, "healthy" if fresh else "unhealthy")))
        mode = s.mode
        if mode is not None:
            hold.append(Belief("mode", (me, mode)))
        else:
            forget.append(("mode", me))
        level = charge_level(s.battery_remaining)
        if level is not None and s.battery_remaining is not None:
            hold.append(Belief("charge", (bat, level)))
            hold.append(Belief("battery_percentage", (bat, int(s.battery_remaining))))
        else:
            forget += [("charge", bat), ("battery_percentage", bat)]
        if s.home is not None:
            lat, lon, alt = s.home
            hold.append(Belief("home", (me, (_r(lat, 7), _r(lon, 7), _r(alt, 2)))))
        else:
            forget.append(("home", me))
        return hold, forget

    def update(self, memory: BeliefMemory, now_s: float | None = None) -> None:
        if now_s is None:
            if self._now is None:
                raise ValueError("CommonBeliefUpdater.update needs now_s or a now() clock")
            now_s = self._now()
        hold, forget = self.beliefs_for(self._state(), now_s)
        for pred, obj in forget:
            memory.forget(pred, obj)
        memory.add_all(hold)


def _r(x: float, digits: int) -> float:
    return round(float(x), digits) + 0.0  # + 0.0: no -0.0


@dataclass
class UpdaterStats:
    """How often an updater ran and failed."""

    runs: int = 0
    errors: int = 0
    last_run_s: float | None = None
    last_error: str | None = None


class BeliefUpdaterRunner:
    """Calls each updater at its own period on the autopilot's clock, in one daemon thread.

    ``now`` is the autopilot's clock (s); ``wall_until(t)`` the wall seconds until it reaches ``t``
    (``AutopilotClock.wall_until``; without it the clock is assumed to run at wall speed). The thread
    sleeps at most 50 ms of wall time between looks at the clock, so a sped-up or jumping clock is
    followed. An updater that raises is logged and called again at its next period. A clock that jumps
    back by more than a second (the autopilot rebooted) restarts the schedule.
    """

    POLL_S = 0.05

    def __init__(self, memory: BeliefMemory, updaters: Iterable[BeliefUpdaterLike],
                 now: Callable[[], float], wall_until: Callable[[float], float] | None = None) -> None:
        self.memory = memory
        self.updaters: Sequence[BeliefUpdaterLike] = list(updaters)
        names = [u.name for u in self.updaters]
        if len(set(names)) != len(names):
            raise ValueError(f"belief updater names must be unique: {names}")
        for u in self.updaters:
            if not u.period_s > 0:
                raise ValueError(f"belief updater {u.name}: period_s must be positive")
        self._now = now
        self._wall_until = wall_until
        self._due: dict[str, float | None] = {u.name: None for u in self.updaters}
        self.stats: dict[str, UpdaterStats] = {u.name: UpdaterStats() for u in self.updaters}
        self._last_t: float | None = None
        self._lock = threading.Lock()  # one run_once at a time
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def run_once(self, now_s: float) -> list[str]:
        """Run every updater due at ``now_s``; return their names."""
        ran: list[str] = []
        with self._lock:
            if self._last_t is not None and now_s < self._last_t - 1.0:
                log.info("autopilot clock went back %.1f s: belief updaters rescheduled",
                         self._last_t - now_s)
                self._due = dict.fromkeys(self._due)
            self._last_t = now_s
            for u in self.updaters:
                due = self._due[u.name]
                if due is not None and now_s < due:
                    continue
                st = self.stats[u.name]
                try:
                    u.update(self.memory, now_s)
                except Exception as exc:  # an updater's bug must not stop the others
                    st.errors += 1
                    st.last_error = f"{type(exc).__name__}: {exc}"
                    log.exception("belief updater %s failed", u.name)
                st.runs += 1
                st.last_run_s = now_s
                # the next period from the schedule, or from now if we fell more than a period behind
                nxt = (due if due is not None else now_s) + u.period_s
                self._due[u.name] = nxt if nxt > now_s else now_s + u.period_s
                ran.append(u.name)
        return ran

    def next_due(self) -> float | None:
        """The earliest autopilot time at which an updater is due (None before the first run)."""
        with self._lock:
            dues = [d for d in self._due.values() if d is not None]
            if len(dues) < len(self._due):
                return None
            return min(dues) if dues else None

    def start(self) -> None:
        """Start the daemon thread (idempotent)."""
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="belief-updaters", daemon=True)
        self._thread.start()

    def close(self, timeout: float = 2.0) -> None:
        """Stop the thread and wait for it."""
        self._stop.set()
        t, self._thread = self._thread, None
        if t is not None:
            t.join(timeout)

    def __enter__(self) -> BeliefUpdaterRunner:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                now_s = self._now()
                self.run_once(now_s)
                nxt = self.next_due()
                if nxt is None:
                    wait = self.POLL_S
                elif self._wall_until is not None:
                    wait = self._wall_until(nxt)
                else:
                    wait = nxt - now_s
            except Exception:
                log.exception("belief updater runner: clock failed")
                wait = self.POLL_S
            self._stop.wait(min(max(wait, 0.001), self.POLL_S))
