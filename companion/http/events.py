"""The queue's events (:mod:`companion.flight.events`).

=========================================  ===========================================================
``GET  /events?since=SEQ``                 the queue's events after SEQ -> ``{"events", "last_seq"}``
``GET  /events/wait?command_id=ID``        the first event of ``kinds`` (comma separated; default
                                           ``FINISHED,FAILED,CANCELLED``) for the command, waiting up
                                           to ``timeout_s`` (default 10, at most 60) ->
                                           ``{"event": {...}}``, or ``{"event": null}`` at the deadline
=========================================  ===========================================================

At most :data:`MAX_WAITERS` waits block a worker thread at once (429 beyond: the verbs keep their threads).
"""

from __future__ import annotations

import threading
import time
from typing import Annotated

from fastapi import APIRouter, Query

from companion.flight import EventKind, QueueEvent
from companion.flight.events import TERMINAL
from companion.http.models import EventModel, EventsResponse, EventWaitResponse
from companion.node import QuadNode
from taskflight_common.httpapi import ApiError

#: longest wait of ``GET /events/wait`` (s)
MAX_WAIT_S = 60.0
#: how many ``GET /events/wait`` may block a worker thread at once (the default pool has 40)
MAX_WAITERS = 16


def _event_model(event: QueueEvent) -> EventModel:
    return EventModel.model_validate(event.to_dict())


def _kinds(text: str | None) -> frozenset[EventKind]:
    if text is None or not text.strip():
        return TERMINAL
    out = set()
    for name in text.split(","):
        name = name.strip().upper()
        try:
            out.add(EventKind[name])
        except KeyError:
            known = ", ".join(k.name for k in EventKind)
            raise ApiError(400, f"query parameter kinds: unknown event kind {name!r} "
                                f"(known: {known})") from None
    return frozenset(out)


def router(node: QuadNode, closing: threading.Event) -> APIRouter:
    """The routes above; setting ``closing`` ends the pending waits."""
    api = APIRouter(tags=["events"])
    waiters = threading.BoundedSemaphore(MAX_WAITERS)

    @api.get("/events", response_model=EventsResponse)
    def events(since: Annotated[int, Query(ge=0, description="the last sequence number seen")] = 0
               ) -> EventsResponse:
        log_ = node.queue.events
        last = log_.last_seq  # read first: every event up to it is in the answer
        found = log_.since(since)
        return EventsResponse(events=[_event_model(e) for e in found],
                              last_seq=max([last] + [e.seq for e in found]))

    @api.get("/events/wait", response_model=EventWaitResponse)
    def wait_event(command_id: Annotated[int, Query(description="the command's id")],
                   kinds: Annotated[str | None, Query(description="comma-separated event kinds (default "
                                                      "FINISHED,FAILED,CANCELLED)")] = None,
                   timeout_s: Annotated[float, Query(ge=0, le=MAX_WAIT_S, description="s")] = 10.0
                   ) -> EventWaitResponse:
        wanted = _kinds(kinds)
        if not waiters.acquire(blocking=False):
            raise ApiError(429, f"too many waiting requests (at most {MAX_WAITERS})")
        try:
            deadline = time.monotonic() + timeout_s
            while True:  # in slices, so that closing the server ends the wait
                left = deadline - time.monotonic()
                event = node.queue.events.wait_for(command_id, wanted, max(0.0, min(left, 0.5)))
                if event is not None or left <= 0.5 or closing.is_set():
                    return EventWaitResponse(event=_event_model(event) if event is not None else None)
        finally:
            waiters.release()

    return api
