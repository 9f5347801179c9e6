"""A stream of what happened, for followers that long-poll (``GET /mission/events``, ``/behaviors/events``).

Seed 000 Fig. 5 gives each executor a status to poll; an operator following a mission (or a ground
station) wants to be told instead: a node started, waits (and for what), failed (and why), is tried
again, the failure policy was applied. :class:`EventStream` keeps the recent events, each a JSON object
with a sequence number ``seq`` (1, 2, ... for the life of the stream) and the time ``t`` (autopilot
seconds), and lets a reader ask for what came after the last ``seq`` it saw, waiting up to a deadline
when nothing has (the queue's :class:`~companion.flight.events.EventLog` does the same for commands).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any


class EventStream:
    """Recent events (at most ``keep``): added by :meth:`record`, read by :meth:`since` and :meth:`wait`."""

    def __init__(self, now: Callable[[], float] | None = None, keep: int = 2000) -> None:
        self._now = now
        self._events: deque[dict[str, Any]] = deque(maxlen=keep)
        self._cond = threading.Condition()
        self._seq = 0

    def record(self, event: str, **fields: Any) -> dict[str, Any]:
        """Append one event (``event`` is its kind, e.g. ``node_started``) and wake the waiting readers."""
        t = self._now() if self._now is not None else None
        with self._cond:
            self._seq += 1
            item = {"seq": self._seq, "t": None if t is None else round(t, 3), "event": event, **fields}
            self._events.append(item)
            self._cond.notify_all()
        return item

    @property
    def last_seq(self) -> int:
        with self._cond:
            return self._seq

    def since(self, seq: int = 0) -> list[dict[str, Any]]:
        """The kept events after ``seq``."""
        with self._cond:
            return [e for e in self._events if e["seq"] > seq]

    def wait(self, seq: int, timeout_s: float, stop: threading.Event | None = None) -> list[dict[str, Any]]:
        """The events after ``seq``; if there are none yet, wait for one up to ``timeout_s`` (wall seconds,
        in slices so that ``stop`` ends the wait early). Empty at the deadline."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                found = [e for e in self._events if e["seq"] > seq]
                left = deadline - time.monotonic()
                if found or left <= 0 or (stop is not None and stop.is_set()):
                    return found
                self._cond.wait(min(left, 0.5))
