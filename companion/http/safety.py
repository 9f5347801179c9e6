"""Going home and the safety monitor on the control surface (served with the executive layer).

=====================  ==========================================================================
``POST /rtl``          ``{"requester": "operator", "altitude": 8, "speed": 2}`` (all optional):
                       the RTL behavior (fly home inside the envelope, land, measured landed at
                       home: :mod:`companion.behaviors.library.rtl`) as the caller's requester ->
                       the activation's answer; 409 with the coordinator's reason when it is
                       refused (not flying, a stronger requester holds the vehicle); 403 for
                       ``emergency`` (the companion's own safety monitor only)
``GET  /safety``       what the safety monitor watches, its thresholds, the last values it
                       computed (charge left and needed), its decisions (newest last)
=====================  ==========================================================================
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field

from companion.behaviors.activation import ActivationError, request_from
from companion.behaviors.system import ExecutiveLayer
from companion.http.auth import Role, requester_for
from companion.http.behaviors import ActivationAnswer
from companion.safety import SafetyMonitor
from companion.safety.monitor import REQUESTER as EMERGENCY
from taskflight_common.httpapi import ApiError


class RtlRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")

    requester: str | None = Field(None, description="default: the caller's token's role; may lower it "
                                                    "(mission), never raise it (emergency is the safety "
                                                    "monitor's)")
    altitude: float | None = Field(None, description="the lowest altitude to return at (m above home); "
                                                     "default: the current altitude, held in the envelope")
    speed: float | None = Field(None, description="horizontal speed home (m/s; default the queue's limit)")


class SafetyView(BaseModel):
    enabled: bool
    watching: list[str]
    thresholds: dict[str, Any]
    checks: int
    values: dict[str, Any]
    last_decision: dict[str, Any] | None
    decisions: list[dict[str, Any]]


def router(layer: ExecutiveLayer, monitor: SafetyMonitor | None) -> APIRouter:
    """The routes above; without a monitor ``GET /safety`` says it is off."""
    app = APIRouter(tags=["safety"])

    @app.post("/rtl", response_model=ActivationAnswer)
    def rtl(role: Role, body: RtlRequest | None = None) -> ActivationAnswer:
        """Return home and land: the RTL behavior as the caller's requester (its token's role, or lower;
        refused: 409, the reason)."""
        body = body or RtlRequest.model_validate({})
        if body.requester == EMERGENCY:
            raise ApiError(403, "requester: emergency is the companion's own safety monitor, not a caller")
        requester = requester_for(role, body.requester, layer.catalog.requester_priority)
        params = {k: v for k, v in (("altitude", body.altitude), ("speed", body.speed)) if v is not None}
        try:
            req = request_from({"behavior": "RTL", "params": params}, requester)
            layer.coordinator.check(req)
        except ActivationError as exc:
            raise ApiError(400, f"format: {exc}") from None
        answer = layer.coordinator.activate(req)
        if not answer.accepted:
            raise ApiError(409, f"RTL refused: {answer.reason}")
        return ActivationAnswer(**answer.to_dict())

    @app.get("/safety", response_model=SafetyView)
    def safety() -> SafetyView:
        """The safety monitor: what it watches, its thresholds, its last values and decisions."""
        if monitor is None:
            return SafetyView(enabled=False, watching=[], thresholds={}, checks=0, values={},
                              last_decision=None, decisions=[])
        return SafetyView(**monitor.status())

    return app
