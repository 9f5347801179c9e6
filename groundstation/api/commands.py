"""``/api/commands``: one command to several vehicles, answered per vehicle; ``/api/fleet/rtl``: every vehicle
home."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request

from groundstation.companions import ApiError
from groundstation.schemas import MultiCommand, MultiCommandAnswer

from . import each_vehicle, service_of

router = APIRouter(tags=["commands"])


@router.post("/commands", response_model=MultiCommandAnswer)
def command_many(request: Request, body: MultiCommand) -> Any:
    """Every target named in the request; each answers on its own (one unreachable does not stop the
    others). Each vehicle's command is audited."""
    return {"results": _many(request, body.command, list(dict.fromkeys(body.vehicles)))}


@router.post("/fleet/rtl", response_model=MultiCommandAnswer)
def fleet_rtl(request: Request) -> Any:
    """Every vehicle of the fleet (registered or heard) home: each companion's RTL as the operator, each
    answering on its own (one unreachable or refusing does not stop the others); audited per vehicle, and
    one ``rtl`` event with every answer."""
    svc = service_of(request)
    targets = [v["id"] for v in svc.fleet.snapshot()]
    if not targets:
        raise ApiError(409, "no vehicle in the fleet")
    results = _many(request, "rtl", targets)
    ok = [r["vehicle"] for r in results if r["ok"]]
    refused = {r["vehicle"]: r["error"] for r in results if not r["ok"]}
    svc.emit("rtl", f"fleet RTL: {len(ok)} of {len(results)} vehicles returning"
             + (f"; refused: {refused}" if refused else ""),
             severity="warning" if refused else "info", data={"returning": ok, "refused": refused})
    return {"results": results}


def _many(request: Request, command: str, targets: list[int]) -> list[dict[str, Any]]:
    svc = service_of(request)
    return each_vehicle(request, command, targets, lambda vid: svc.command(vid, command))
