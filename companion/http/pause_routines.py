"""The queue's pause routines (seed 000 Sec. V): ``POST /pause_direct`` and ``/pause_after_current``
(optional body ``{"routine_id": "hover"}``), ``GET /pause_routines`` (their ids)."""

from __future__ import annotations

from fastapi import APIRouter

from companion.behaviors.system import ExecutiveLayer
from companion.http.auth import Role
from companion.http.models import PauseRequest, PauseRoutinesResponse, VerbResponse
from companion.http.queue import hold_check, verb
from companion.node import QuadNode


def router(node: QuadNode, layer: ExecutiveLayer | None = None) -> APIRouter:
    api = APIRouter(tags=["pause routines"])

    @api.post("/pause_direct", response_model=VerbResponse)
    def pause_direct(role: Role, body: PauseRequest | None = None) -> VerbResponse:
        hold_check(layer, role, "pause_direct")
        return verb(node, node.pause_direct, body.routine_id if body is not None else None)

    @api.post("/pause_after_current", response_model=VerbResponse)
    def pause_after_current(role: Role, body: PauseRequest | None = None) -> VerbResponse:
        hold_check(layer, role, "pause_after_current")
        return verb(node, node.pause_after_current, body.routine_id if body is not None else None)

    @api.get("/pause_routines", response_model=PauseRoutinesResponse)
    def pause_routines() -> PauseRoutinesResponse:
        return PauseRoutinesResponse(pause_routines=list(node.queue.catalog.ids()))

    return api
