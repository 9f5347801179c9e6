"""``/api/events``, ``/api/audit``, ``/api/missions``, ``/api/whoami``: alerts, history and the audit log."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query, Request

from groundstation.schemas import AssignmentList, AuditList, EventList, FenceOut, MissionList, WhoAmI

from . import principal_of, service_of

router = APIRouter(tags=["history"])


@router.get("/events", response_model=EventList)
def list_events(request: Request, since: Annotated[int, Query(ge=0, le=2**62)] = 0,
                limit: Annotated[int, Query(ge=1, le=5000)] = 1000,
                kind: Annotated[str | None, Query(max_length=40)] = None) -> Any:
    """Alerts and history after event ``since``: failsafe, override, link_lost, confirmation_required,
    task_added / task_state / task_cancelled, conflict, resolved, ..."""
    rows = service_of(request).db.events(since, limit, kind)
    return {"events": rows, "last_id": rows[-1]["id"] if rows else since}


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
