"""Command events of the queue: what the layers above wait on or subscribe to (seed 000 Sec. V, Fig. 5).

Seed 000 Sec. III-B: a TST executor follows its flight commands by their status (Fig. 5's execution
info: started, finished, paused, aborted...). The paper's QAPI only offers status to poll; the
layers built on the queue (behaviors, executors) need to *wait* for a command's end. The queue
publishes a :class:`QueueEvent` for every change of a command's life; an :class:`EventLog` keeps
the recent ones and lets a caller

* subscribe a callback (called in the thread that caused the event, after the queue released its
  lock; it must be quick and must not block),
* wait for an event with a deadline (``wait_for(command_id, {EventKind.FINISHED}, timeout)``),
* read what happened since a sequence number (``since(seq)``), for pollers and the HTTP surface.

Command ids are unique for the life of the process (:func:`new_command_id`), across resets and
queues, so an event can never be mistaken for one of an earlier command at the same index.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from enum import Enum

log = logging.getLogger(__name__)

_ids = itertools.count(1)
_ids_lock = threading.Lock()


def new_command_id() -> int:
    """The next command id of this process (never reused)."""
    with _ids_lock:
        return next(_ids)


class EventKind(Enum):
    """What happened to a command (or, for OVERRIDDEN and RESET, to the queue)."""

    ADDED = "ADDED"
    STARTED = "STARTED"  # its execution began (first start)
    FINISHED = "FINISHED"  # its end condition held; the queue moved on
    PAUSED = "PAUSED"  # a pause routine interrupted it
    RESUMED = "RESUMED"  # it continues after a pause or a stop
    STOPPED = "STOPPED"  # stop(): it rests where it is
    RETARGETED = "RETARGETED"  # its target, speed or heading changed in flight
    DEFERRED = "DEFERRED"  # a verb waits until the take-off may be stopped
    FAILED = "FAILED"  # it was given up (e.g. a refused take-off)
    CANCELLED = "CANCELLED"  # reset() dropped it before it finished
    OVERRIDDEN = "OVERRIDDEN"  # someone else took the vehicle while it ran
    RESET = "RESET"  # the queue was cleared (a new generation starts)


#: The kinds after which a command never runs again.
TERMINAL = frozenset({EventKind.FINISHED, EventKind.FAILED, EventKind.CANCELLED})


@dataclass(frozen=True)
class QueueEvent:
    """One event. ``seq`` orders all events of one log; ``t_s`` is the queue's time (None: no tick yet)."""

    seq: int
    kind: EventKind
    command_id: int | None
    index: int | None
    generation: int
    t_s: float | None
    detail: str = ""

    def to_dict(self) -> dict[str, object]:
        return {"seq": self.seq, "kind": self.kind.value, "command_id": self.command_id,
                "index": self.index, "generation": self.generation, "t_s": self.t_s,
                "detail": self.detail}


Subscriber = Callable[[QueueEvent], None]


class EventLog:
    """The recent events, their subscribers and their waiters (see module docstring).

    The queue (its one writer) calls :meth:`record` under its own lock and :meth:`dispatch` after
    releasing it, so subscribers may call the queue's verbs.
    """

    def __init__(self, keep: int = 2000) -> None:
        self._events: deque[QueueEvent] = deque(maxlen=keep)
        self._cond = threading.Condition()
        self._seq = 0
        self._subscribers: list[Subscriber] = []

    def record(self, kind: EventKind, command_id: int | None, index: int | None, generation: int,
               t_s: float | None, detail: str = "") -> QueueEvent:
        with self._cond:
            self._seq += 1
            event = QueueEvent(self._seq, kind, command_id, index, generation, t_s, detail)
            self._events.append(event)
            self._cond.notify_all()
        log.debug("event %s", event)
        return event

    def dispatch(self, events: Iterable[QueueEvent]) -> None:
        """Call the subscribers with ``events`` (the caller holds no queue lock)."""
        subscribers = list(self._subscribers)
        for event in events:
            for fn in subscribers:
                try:
                    fn(event)
                except Exception:
                    log.exception("event subscriber failed on %s", event)

    # --- readers ------------------------------------------------------------------------------------
    def subscribe(self, fn: Subscriber) -> Callable[[], None]:
        """Call ``fn`` with every later event; returns the function that unsubscribes it."""
        self._subscribers.append(fn)

        def unsubscribe() -> None:
            if fn in self._subscribers:
                self._subscribers.remove(fn)
        return unsubscribe

    @property
    def last_seq(self) -> int:
        with self._cond:
            return self._seq

    def since(self, seq: int = 0) -> list[QueueEvent]:
        """The kept events with a sequence number above ``seq``."""
        with self._cond:
            return [e for e in self._events if e.seq > seq]

    def wait(self, predicate: Callable[[QueueEvent], bool], timeout_s: float,
             after_seq: int = 0) -> QueueEvent | None:
        """The first kept event after ``after_seq`` matching ``predicate``; waits up to ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                for e in self._events:
                    if e.seq > after_seq and predicate(e):
                        return e
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)

    def wait_for(self, command_id: int, kinds: Iterable[EventKind] = TERMINAL,
                 timeout_s: float = 60.0) -> QueueEvent | None:
        """The first event of ``kinds`` for ``command_id`` (already happened or within ``timeout_s``)."""
        wanted = frozenset(kinds)
        return self.wait(lambda e: e.command_id == command_id and e.kind in wanted, timeout_s)
