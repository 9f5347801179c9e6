"""``GET /status``: the QAPI status (seed 000 Sec. V) with the flight phase, the link, the vehicle and
the node; ``awaits_operator`` when the executive layer is served."""

from __future__ import annotations

from fastapi import APIRouter

from companion.behaviors.system import ExecutiveLayer
from companion.http.models import StatusResponse
from companion.node import QuadNode


def router(node: QuadNode, behaviors: ExecutiveLayer | None) -> APIRouter:
    api = APIRouter(tags=["status"])

    @api.get("/status", response_model=StatusResponse)
    def status() -> StatusResponse:
        out = node.status()
        if behaviors is not None:
            out["awaits_operator"] = behaviors.awaits_operator()
        return StatusResponse.model_validate(out)

    return api
