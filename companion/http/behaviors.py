"""The executive layer on the control surface (seed 001 Sec. 6.2.2, 6.2.4).

=====================================  ================================================================
``POST /behaviors/activate``           ``{"text": "GO_TO_POINT coordinate: (10, 0, 5)", "requester":
                                       "mission"}`` or ``{"behavior": "GO_TO_POINT", "params":
                                       {"coordinate": [10, 0, 5]}, "requester": "mission"}`` ->
                                       ``{"accepted", "reason", "activation_id", ...}`` (a request the
                                       coordinator rejects is an answer, 200; a malformed one a 400)
``POST /behaviors/inhibit``            ``{"behavior": "GO_TO_POINT" | "activation_id": "a7",
                                       "requester": "operator"}`` -> same shape
``POST /behaviors/check``              the format check only -> ``{"ok": true, "params": {...},
                                       "text": "..."}``; 400 with the reason
``GET  /behaviors``                    the catalog, the active behaviors (requester, start time), the
                                       recent terminations with their cause, recent requests, processes
``POST /behaviors/joystick``           a stick sample ``{"values": [vn, ve, vd, yaw_rate], "validity_s"}``
                                       for FOLLOW_EXTERNAL_VELOCITY (409 while no behavior uses it)
``GET  /beliefs?query=...``            the bindings of a query (``object(?x, battery), charge(?x, ?y)``);
                                       without a query, every belief
``POST /beliefs``                      ``{"add": ["charge(92, empty)"], "remove": ["visible(32)"]}``
                                       (all parsed first: a bad one changes nothing)
=====================================  ================================================================

A malformed body or query answers 400 with the reason and changes nothing.

Requesters come from credentials (:mod:`companion.http.auth`): an activation's or inhibition's
requester is the caller's token's role; the body's ``requester`` may lower it, never raise it (403).
A request the coordinator refuses answers 409 ``{"error": reason, "accepted": false, "reason": ...}``
and changes nothing. A joystick sample is taken from a caller with at least the priority of the
requester holding the vehicle (else 409).
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query
from pydantic import BaseModel, ConfigDict, Field

from companion.behaviors.activation import ActivationError, format_activation, request_from
from companion.behaviors.belief_syntax import BeliefError, bindings_to_json, parse_belief, parse_query
from companion.behaviors.coordinator import jsonable
from companion.behaviors.processes import ProcessError
from companion.behaviors.system import ExecutiveLayer
from companion.flight import ExternalDataError
from companion.http.auth import Role, requester_for
from taskflight_common.httpapi import ApiError


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ActivateRequest(_Strict):
    text: str | None = Field(None, description="the text form, e.g. 'ROTATE angle: 45'")
    behavior: str | None = Field(None, description="the structured form: the behavior's name")
    params: dict[str, Any] | None = Field(None, description="the structured form's parameters")
    requester: str | None = Field(None, description="the caller's role (its token's) unless lowered here: "
                                                    "operator, mission (emergency is no caller's)")


class InhibitRequest(_Strict):
    behavior: str | None = None
    activation_id: str | None = None
    requester: str | None = Field(None, description="the caller's role unless lowered here")


class ActivationAnswer(BaseModel):
    accepted: bool
    reason: str
    activation_id: str | None = None
    behavior: str | None = None
    stopped: list[str] = []
    started_defaults: list[str] = []


class CheckAnswer(BaseModel):
    ok: bool
    behavior: str
    params: dict[str, Any]
    text: str


class BehaviorsView(BaseModel):
    catalog: dict[str, Any]
    active: list[dict[str, Any]]
    ended: list[dict[str, Any]]
    requests: list[dict[str, Any]]
    processes: list[dict[str, Any]]
    monitor_cycles: int


class JoystickSample(_Strict):
    values: list[float] = Field(..., min_length=4, max_length=4,
                                description="v_north, v_east, v_down (m/s), yaw rate (deg/s)")
    validity_s: float = Field(0.5, gt=0, le=5.0)


class JoystickAnswer(BaseModel):
    accepted: bool


class BeliefsView(BaseModel):
    query: str | None
    bindings: list[dict[str, Any]] = Field(description="one mapping of variable to value per solution")
    beliefs: list[str] = Field(description="every belief (without a query)")


class BeliefChange(_Strict):
    add: list[str] = []
    remove: list[str] = []


class BeliefChangeAnswer(BaseModel):
    added: list[str]
    retracted: list[str]
    removed: list[str]


def router(layer: ExecutiveLayer) -> APIRouter:
    """The routes above."""
    app = APIRouter(tags=["behaviors"])
    priority = layer.catalog.requester_priority

    def request_of(body: ActivateRequest, requester: str) -> Any:
        if (body.text is None) == (body.behavior is None):
            raise ApiError(400, "give either 'text' or 'behavior' (+ 'params')")
        if body.text is not None:
            if body.params is not None:
                raise ApiError(400, "'params' goes with 'behavior', not with 'text'")
            return request_from(body.text, requester)
        return request_from({"behavior": body.behavior, "params": body.params or {}}, requester)

    def answer(result: Any) -> ActivationAnswer:
        if not result.accepted:
            raise ApiError(409, result.reason, **result.to_dict())
        return ActivationAnswer(**result.to_dict())

    @app.post("/behaviors/activate", response_model=ActivationAnswer)
    def activate(body: ActivateRequest, role: Role) -> ActivationAnswer:
        requester = requester_for(role, body.requester, priority)
        try:
            req = request_of(body, requester)
            layer.coordinator.check(req)  # a malformed request is a 400; a refused one a 409
        except ActivationError as exc:
            raise ApiError(400, f"format: {exc}") from None
        return answer(layer.coordinator.activate(req))

    @app.post("/behaviors/inhibit", response_model=ActivationAnswer)
    def inhibit(body: InhibitRequest, role: Role) -> ActivationAnswer:
        requester = requester_for(role, body.requester, priority)
        target = body.behavior or body.activation_id
        if not target or (body.behavior and body.activation_id):
            raise ApiError(400, "give either 'behavior' or 'activation_id'")
        return answer(layer.coordinator.inhibit(target, requester))

    @app.post("/behaviors/check", response_model=CheckAnswer)
    def check(body: ActivateRequest, role: Role) -> CheckAnswer:
        try:
            as_role = role if role in priority else priority[-1]  # an observer checks as the lowest
            req = request_of(body, requester_for(as_role, body.requester, priority))
            params = layer.coordinator.check(req)
        except ActivationError as exc:
            raise ApiError(400, f"format: {exc}") from None
        return CheckAnswer(ok=True, behavior=req.behavior, params=jsonable(params),
                           text=format_activation(req.behavior, params))

    @app.get("/behaviors", response_model=BehaviorsView)
    def behaviors() -> BehaviorsView:
        return BehaviorsView(catalog=layer.catalog.to_dict(), **layer.status())

    @app.post("/behaviors/joystick", response_model=JoystickAnswer)
    def joystick(body: JoystickSample, role: Role) -> JoystickAnswer:
        why = layer.coordinator.authority(role, "joystick")
        if why is not None:
            raise ApiError(409, why)
        try:
            return JoystickAnswer(accepted=layer.joystick.push(body.values, body.validity_s))
        except ProcessError as exc:
            raise ApiError(409, str(exc)) from None
        except ExternalDataError as exc:
            raise ApiError(400, f"malformed sample: {exc}") from None

    @app.get("/beliefs", response_model=BeliefsView)
    def beliefs(query: Annotated[str | None, Query(description="e.g. object(?x, battery), charge(?x, ?y)")]
                = None) -> BeliefsView:
        if query is None or not query.strip():
            return BeliefsView(query=None, bindings=[], beliefs=[str(b) for b in layer.beliefs.beliefs()])
        try:
            q = parse_query(query)
        except BeliefError as exc:
            raise ApiError(400, str(exc)) from None
        return BeliefsView(query=query, bindings=bindings_to_json(layer.beliefs.consult(q)), beliefs=[])

    @app.post("/beliefs", response_model=BeliefChangeAnswer)
    def change_beliefs(body: BeliefChange) -> BeliefChangeAnswer:
        try:
            adds = [parse_belief(t) for t in body.add]
            removes = [parse_belief(t) for t in body.remove]
        except BeliefError as exc:
            raise ApiError(400, str(exc)) from None
        retracted = [str(b) for a in adds for b in layer.beliefs.add(a)]
        removed = [str(b) for b in removes if layer.beliefs.remove(b)]
        return BeliefChangeAnswer(added=[str(a) for a in adds], retracted=retracted, removed=removed)

    return app
