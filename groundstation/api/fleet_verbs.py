"""``/api/fleet/land``, ``/api/fleet/hold`` and ``/api/fence``: the verbs an operator reaches for across the
whole fleet (QGroundControl's and Mission Planner's "land all" and "pause all"; ``/api/fleet/rtl`` is in
:mod:`.commands`), and the operator's fence sent to every vehicle's autopilot.

Each vehicle answers on its own: one unreachable or refusing does not stop the others, and each answer is
audited. ``hold``: every vehicle's mission paused with the ``hover`` routine (seed 000 Sec. VII, the
operator's break-in: the vehicle holds where it is until resumed). ``land``: the companion's LAND behavior
as the operator (lands where each vehicle is). ``POST /api/fence``: the polygon becomes the service's
operational fence (tasks outside it refused, the map draws it) and each companion uploads it to its
autopilot's fence (the MAVLink mission protocol, MAV_MISSION_TYPE_FENCE) and enables it.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from pydantic import BaseModel, ConfigDict, Field

from groundstation.companions import ApiError
from groundstation.schemas import MultiCommandAnswer
from groundstation.service import fence_of

from . import each_vehicle, service_of

router = APIRouter(tags=["commands"])
#: a companion's answer to ``POST /fence`` may take its whole upload and three parameter round trips, each
#: with its own retries (:mod:`companion.link.fence`): more than a verb's 5 s on a loaded machine
FENCE_CALL_S = 45.0


class FleetVerb(BaseModel):
    """Optional body of ``/api/fleet/land`` and ``/api/fleet/hold``: the vehicles (default: all)."""

    model_config = ConfigDict(extra="forbid")
    vehicles: list[int] | None = Field(None, min_length=1, max_length=256)


class FenceRequest(BaseModel):
    """The operator's fence: an inclusion polygon ``[[lat, lon], ...]``."""

    model_config = ConfigDict(extra="forbid")
    points: list[list[float]] = Field(..., min_length=3, max_length=100)
    vehicles: list[int] | None = Field(None, min_length=1, max_length=256,
                                       description="the vehicles whose autopilots get it (default: all)")
    enable: bool = Field(True, description="enable the autopilots' polygon fence")


class FenceAnswerOut(BaseModel):
    points: list[list[float]]
    results: list[dict[str, Any]]


def _targets(request: Request, asked: list[int] | None) -> list[int]:
    fleet = [v["id"] for v in service_of(request).fleet.snapshot()]
    if asked is None:
        if not fleet:
            raise ApiError(409, "no vehicle in the fleet")
        return fleet
    unknown = sorted(set(asked) - set(fleet))
    if unknown:
        raise ApiError(404, f"vehicles: no vehicle {', '.join(map(str, unknown))}")
    return list(dict.fromkeys(asked))


def _report(request: Request, kind: str, what: str, results: list[dict[str, Any]]) -> None:
    ok = [r["vehicle"] for r in results if r["ok"]]
    refused = {r["vehicle"]: r["error"] for r in results if not r["ok"]}
    service_of(request).emit(kind, f"fleet {what}: {len(ok)} of {len(results)} vehicles"
                             + (f"; refused: {refused}" if refused else ""),
                             severity="warning" if refused else "info", data={"ok": ok, "refused": refused})


@router.post("/fleet/land", response_model=MultiCommandAnswer)
def fleet_land(request: Request, body: FleetVerb | None = None) -> Any:
    """Every vehicle (or those named) lands where it is: each companion's LAND behavior as the operator."""
    svc = service_of(request)
    targets = _targets(request, body.vehicles if body else None)
    results = each_vehicle(request, "land", targets, lambda vid: svc.command(vid, "land"))
    _report(request, "land", "land", results)
    return {"results": results}


@router.post("/fleet/hold", response_model=MultiCommandAnswer)
def fleet_hold(request: Request, body: FleetVerb | None = None) -> Any:
    """Every vehicle (or those named) holds in place: its mission paused with the ``hover`` routine (resume
    each with ``POST /api/vehicles/{vid}/resume`` or ``/api/commands`` ``resume``)."""
    svc = service_of(request)
    targets = _targets(request, body.vehicles if body else None)
    results = each_vehicle(request, "pause", targets,
                           lambda vid: svc.command(vid, "pause", {"routine_id": "hover"}))
    _report(request, "hold", "hold", results)
    return {"results": results}


@router.post("/fence", response_model=FenceAnswerOut)
def post_fence(request: Request, body: FenceRequest) -> Any:
    """The operator's fence: checked (a simple polygon of valid points, else 400 and nothing changes),
    made the service's operational fence, and sent to each vehicle's autopilot (answered per vehicle:
    ``answer`` is the companion's ``{vertices, enabled, fence_type}``)."""
    svc = service_of(request)
    try:
        fence = fence_of(body.points)
    except ValueError as exc:
        raise ApiError(400, str(exc)) from None
    targets = _targets(request, body.vehicles)
    points = [[float(p[0]), float(p[1])] for p in body.points]
    svc.fence_points = points
    svc.station.ledger.fence = fence

    def one(vid: int) -> dict[str, Any]:
        status, answer = svc.call(vid, "POST", "/fence", {"points": points, "enable": body.enable},
                                  timeout_s=FENCE_CALL_S)
        ok = status == 200
        error = None if ok else answer.get("error") if isinstance(answer, dict) else str(answer)
        return {"vehicle": vid, "command": "fence", "ok": ok, "status": status, "answer": answer,
                "error": error}

    results = each_vehicle(request, "fence", targets, one)
    _report(request, "fence", f"fence of {len(points)} vertices", results)
    return {"points": points, "results": results}
