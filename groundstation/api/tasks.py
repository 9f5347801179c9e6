"""``/api/tasks``: team tasking (seed 003 Sec. II, the Team Control interface)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Path, Request
from pydantic import BaseModel, Field

from groundstation.schemas import (
    ErrorAnswer,
    ReleaseRequest,
    TaskAdded,
    TaskCancelled,
    TaskList,
    TaskRequest,
    TasksReleased,
)
from taskflight_common.httpapi import ApiError

from . import audited, service_of

router = APIRouter(tags=["tasks"])


@router.post("/tasks", response_model=TaskAdded, status_code=201,
             responses={409: {"model": ErrorAnswer, "description": "more vehicles asked for than are free: "
                                                                   "the offer of a smaller N"}})
def add_task(request: Request, body: TaskRequest) -> Any:
    """A team task; the vehicles divide the tasks among themselves (seed 003 Sec. III-B)."""
    svc = service_of(request)
    return audited(request, "add_task", body.type, body.model_dump(exclude_none=True),
                   lambda: svc.add_task(body))


@router.get("/tasks", response_model=TaskList)
def list_tasks(request: Request) -> Any:
    """Every task with its state, assignee and cost."""
    return {"tasks": service_of(request).tasks()}


@router.delete("/tasks/{tid}", response_model=TaskCancelled)
def cancel_task(request: Request, tid: Annotated[int, Path(ge=1, le=10**9)]) -> Any:
    """Cancel a task, or every live piece of a divided task (its group id)."""
    svc = service_of(request)
    return audited(request, "cancel_task", f"task {tid}", None, lambda: {"cancelled": svc.cancel_task(tid)})


@router.post("/tasks/release", response_model=TasksReleased,
             responses={409: {"model": ErrorAnswer, "description": "a task named is not held"}})
def release_tasks(request: Request, body: Annotated[ReleaseRequest | None, Body()] = None) -> Any:
    """Release held tasks (restored from an earlier run, kept from the team) to the team: the vehicles
    divide and fly them. Without ``ids``: every held task."""
    svc = service_of(request)
    ids = body.ids if body is not None else None
    return audited(request, "release_tasks", "tasks" if ids is None else f"tasks {ids}",
                   body.model_dump() if body is not None else None,
                   lambda: {"released": svc.release_tasks(ids), "held": list(svc.station.held())})


class RedivideRequest(BaseModel):
    vehicles: int | None = Field(default=None, ge=1, le=255,
                                 description="the new N (absent: the vehicles that can fly it now, "
                                             "those holding one of its pieces and the free ones)")


class TaskRedivided(BaseModel):
    group: int = Field(description="the divided task")
    ids: list[int] = Field(description="its new pieces (the old live ones are cancelled)")
    vehicles: int = Field(description="the N used")


@router.post("/tasks/{tid}/redivide", response_model=TaskRedivided,
             responses={409: {"model": ErrorAnswer, "description": "not a divided task with live pieces"}})
def redivide_task(request: Request, tid: Annotated[int, Path(ge=1, le=10**9)],
                  body: RedivideRequest | None = None) -> Any:
    """Re-divide a border patrol or area scan among N vehicles (seed 003 Sec. II); the station does it by
    itself when vehicles drop out of it."""
    svc = service_of(request)
    n = body.vehicles if body is not None else None

    def run() -> dict[str, Any]:
        try:
            ids = svc.station.redivide(tid, n)
        except ValueError as exc:
            raise ApiError(409, str(exc)) from None
        return {"group": tid, "ids": list(ids), "vehicles": len(ids)}

    return audited(request, "redivide_task", f"task {tid}", body.model_dump() if body else None, run)
