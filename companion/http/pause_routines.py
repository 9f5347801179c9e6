"""The queue's pause routines (seed 000 Sec. V): ``POST /pause_direct`` and ``/pause_after_current``
(optional body ``{"routine_id": "hover"}``), ``GET /pause_routines`` (their ids)."""

from __future__ import annotations

from fastapi import APIRouter

from companion.http.models import PauseRequest, PauseRoutinesResponse, VerbResponse
from companion.http.queue import verb
from companion.node import QuadNode


def router(node: QuadNode) -> APIRouter:
    api = APIRouter(tags=["pause routines"])

    @api.post("/pause_direct", response_model=VerbResponse)
    def pause_direct(body: PauseRequest | None = None) -> VerbResponse:
        return verb(node, node.pause_direct, body.routine_id if body is not None else None)

    @api.post("/pause_after_current", response_model=VerbResponse)
    def pause_after_current(body: PauseRequest | None = None) -> VerbResponse:
        return verb(node, node.pause_after_current, body.routine_id if body is not None else None)

    @api.get("/pause_routines", response_model=PauseRoutinesResponse)
    def pause_routines() -> PauseRoutinesResponse:
        return PauseRoutinesResponse(pause_routines=list(node.queue.catalog.ids()))

    return api
