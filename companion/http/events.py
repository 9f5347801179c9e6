"""The queue's events (:mod:`companion.flight.events`), the mission's and the executive layer's.

==============================================  ======================================================
``GET  /events?since=SEQ``                      the queue's events after SEQ -> ``{"events", "last_seq"}``
``GET  /events/wait?command_id=ID``             the first event of ``kinds`` (comma separated; default
                                                ``FINISHED,FAILED,CANCELLED``) for the command, waiting
                                                up to ``timeout_s`` (default 10, at most 60) ->
                                                ``{"event": {...}}``, or ``{"event": null}`` at the
                                                deadline
``GET  /mission/events?since=SEQ&timeout=S``    what the mission did after SEQ (when the mission layer
                                                is served): nodes started, finished, failed (with the
                                                reason), retried, waiting (and for what), the failure
                                                policy applied; waits up to ``timeout`` s (default 0,
                                                at most 60) while there is nothing new ->
                                                ``{"events", "last_seq"}``
``GET  /behaviors/events?since=SEQ&timeout=S``  the executive layer's activations likewise (when it is
                                                served): ``started``, ``ended`` (with the cause),
                                                ``refused`` (with the reason), by behavior and requester
==============================================  ======================================================

At most :data:`MAX_WAITERS` waits block a worker thread at once (429 beyond: the verbs keep their threads).
"""

from __future__ import annotations

import threading
import time
import weakref
from typing import Annotated, Any

from fastapi import APIRouter, Query
from pydantic import BaseModel, Field

from companion.behaviors.coordinator import BehaviorCoordinator
from companion.behaviors.system import ExecutiveLayer
from companion.flight import EventKind, QueueEvent
from companion.flight.events import TERMINAL
from companion.http.models import EventModel, EventsResponse, EventWaitResponse
from companion.mission_service import MissionService
from companion.node import QuadNode
from companion.tst.events import EventStream
from taskflight_common.httpapi import ApiError

#: longest wait of ``GET /events/wait`` (s)
MAX_WAIT_S = 60.0
#: how many ``GET /events/wait`` may block a worker thread at once (the default pool has 40)
MAX_WAITERS = 16


class StreamEvents(BaseModel):
    """The events after ``since`` (oldest first) and the last sequence number to ask from next."""

    events: list[dict[str, Any]] = Field(description="each with seq, t (autopilot s), event and its fields")
    last_seq: int


SINCE_Q = Query(ge=0, description="the last sequence number seen (0: from the oldest kept)")
TIMEOUT_Q = Query(ge=0, le=MAX_WAIT_S, description="wait up to this long (s) while nothing is new")
_behavior_streams: weakref.WeakKeyDictionary[BehaviorCoordinator, EventStream] = weakref.WeakKeyDictionary()
_streams_lock = threading.Lock()


def behavior_events(layer: ExecutiveLayer) -> EventStream:
    """The executive layer's activations as a stream (one per coordinator, attached on first use to
    the coordinator's ``record_listeners``): ``started``, ``ended`` with the cause, ``refused`` with the
    reason."""
    coordinator = layer.coordinator
    with _streams_lock:
        stream = _behavior_streams.get(coordinator)
        if stream is None:
            stream = EventStream(layer.now)
            coordinator.record_listeners.append(lambda record: _behavior_record(stream, record))
            _behavior_streams[coordinator] = stream
        return stream


def _behavior_record(stream: EventStream, r: dict[str, Any]) -> None:
    who = {"behavior": r.get("behavior"), "activation_id": r.get("activation_id"),
           "requester": r.get("requester")}
    if r.get("type") == "behavior" and r.get("event") == "started":
        stream.record("started", **who, params=r.get("params", {}))
    elif r.get("type") == "behavior" and r.get("event") == "terminated":
        stream.record("ended", **who, cause=r.get("cause"), detail=r.get("detail", ""))
    elif r.get("type") == "behavior" and r.get("event") == "start_failed":
        stream.record("refused", **who, kind="activate", reason=f"start: {r.get('reason', '')}")
    elif r.get("type") == "request" and r.get("event") == "rejected":
        stream.record("refused", **who, kind=r.get("kind"), reason=r.get("reason", ""), text=r.get("text"))


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


def router(node: QuadNode, closing: threading.Event, missions: MissionService | None = None,
           behaviors: ExecutiveLayer | None = None) -> APIRouter:
    """The routes above (the mission's with ``missions``, the executive layer's with ``behaviors``);
    setting ``closing`` ends the pending waits."""
    api = APIRouter(tags=["events"])
    waiters = threading.BoundedSemaphore(MAX_WAITERS)

    def long_poll(stream: EventStream, since: int, timeout: float) -> StreamEvents:
        last = stream.last_seq
        if timeout <= 0 or since != last:  # something new, or a sequence from before (resynchronise)
            found = stream.since(since)
        else:
            if not waiters.acquire(blocking=False):
                raise ApiError(429, f"too many waiting requests (at most {MAX_WAITERS})")
            try:
                found = stream.wait(since, timeout, closing)
            finally:
                waiters.release()
        return StreamEvents(events=found, last_seq=max([last] + [e["seq"] for e in found]))

    if missions is not None:
        mission_stream = missions.events

        @api.get("/mission/events", response_model=StreamEvents)
        def mission_events(since: Annotated[int, SINCE_Q] = 0, timeout: Annotated[float, TIMEOUT_Q] = 0.0
                           ) -> StreamEvents:
            return long_poll(mission_stream, since, timeout)

    if behaviors is not None:
        behavior_stream = behavior_events(behaviors)

        @api.get("/behaviors/events", response_model=StreamEvents)
        def behavior_events_route(since: Annotated[int, SINCE_Q] = 0,
                                  timeout: Annotated[float, TIMEOUT_Q] = 0.0) -> StreamEvents:
            return long_poll(behavior_stream, since, timeout)

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
