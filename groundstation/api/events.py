"""``/api/events``, ``/api/alerts``, ``/api/track``, ``/api/audit``, ``/api/missions``, ``/api/whoami``:
alerts (their history, loaded by the UI on every (re)connect, and their acknowledgement), the vehicles'
stored tracks (the replay), history and the audit log."""

from __future__ import annotations

import time
from typing import Annotated, Any

from fastapi import APIRouter, Path, Query, Request

from groundstation.alerts import ALERT_KINDS
from groundstation.companions import ApiError
from groundstation.schemas import (
    AlertList,
    AssignmentList,
    AuditList,
    EventList,
    EventOut,
    FenceOut,
    MissionList,
    TrackOut,
    WhoAmI,
)

from . import audited, principal_of, service_of

router = APIRouter(tags=["history"])


@router.get("/events", response_model=EventList)
def list_events(request: Request, since: Annotated[int, Query(ge=0, le=2**62)] = 0,
                limit: Annotated[int, Query(ge=1, le=5000)] = 1000,
                kind: Annotated[str | None, Query(max_length=40)] = None) -> Any:
    """Alerts and history after event ``since``: failsafe, override, link_lost, confirmation_required,
    task_added / task_state / task_cancelled, conflict, resolved, ..."""
    rows = service_of(request).db.events(since, limit, kind)
    return {"events": rows, "last_id": rows[-1]["id"] if rows else since}


@router.get("/alerts", response_model=AlertList)
def list_alerts(request: Request, limit: Annotated[int, Query(ge=1, le=1000)] = 200) -> Any:
    """The newest ``limit`` alerts (failsafe, override, link_lost, battery_low / battery_critical,
    duplicate_id, confirmation_required, ...) with who acknowledged each: the UI's list after a reload."""
    rows = service_of(request).db.events(kinds=ALERT_KINDS, limit=limit, newest=True)
    return {"alerts": rows, "kinds": list(ALERT_KINDS)}


@router.post("/events/{eid}/ack", response_model=EventOut)
def acknowledge(request: Request, eid: Annotated[int, Path(ge=1, le=2**62)]) -> Any:
    """Acknowledge an alert (audited; every operator's page shows it acknowledged, by whom)."""
    svc, who = service_of(request), principal_of(request)
    return audited(request, "ack", f"event {eid}", None, lambda: svc.acknowledge(eid, who))


@router.get("/track/{vid}", response_model=TrackOut)
def track(request: Request, vid: Annotated[int, Path(ge=1, le=255)],
          since: Annotated[float | None, Query(ge=0, description="epoch s (default: an hour ago)")] = None,
          until: Annotated[float | None, Query(ge=0, description="epoch s (default: now)")] = None) -> Any:
    """A vehicle's stored track between two times (about 1 Hz; the last hour is kept): the replay."""
    now = time.time()
    t1 = now if until is None else until
    t0 = t1 - 3600.0 if since is None else since
    if t0 > t1:
        raise ApiError(400, f"since: {t0} is after until {t1}")
    return {"vehicle": vid, "since": t0, "until": t1, "points": service_of(request).db.track(vid, t0, t1)}


@router.get("/audit", response_model=AuditList)
def audit_log(request: Request, since: Annotated[int, Query(ge=0, le=2**62)] = 0,
              limit: Annotated[int, Query(ge=1, le=5000)] = 1000) -> Any:
    """Every operator command: who, what, when, the answer (refusals included)."""
    return {"entries": service_of(request).db.audit_log(since, limit)}


@router.get("/assignments", response_model=AssignmentList)
def assignments(request: Request, task: Annotated[int | None, Query(ge=1, le=10**9)] = None) -> Any:
    """The history of each task's state and holder (oldest first)."""
    return {"assignments": service_of(request).db.assignments(task)}


@router.get("/missions", response_model=MissionList)
def missions(request: Request, vehicle: Annotated[int | None, Query(ge=1, le=255)] = None) -> Any:
    """The missions given to vehicles, with the companions' answers."""
    return {"missions": service_of(request).db.missions(vehicle)}


@router.get("/whoami", response_model=WhoAmI)
def whoami(request: Request) -> Any:
    who = principal_of(request)
    return {"role": who.role, "name": who.name}


@router.get("/fence", response_model=FenceOut)
def fence(request: Request) -> Any:
    """The fence (tasks with a point outside it are refused, 400), for the map."""
    return {"points": service_of(request).fence_points}
