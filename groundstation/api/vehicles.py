"""``/api/vehicles``: the fleet's state and the Process Monitor's commands to one vehicle (seed 003
Sec. II "send high-level commands to individual processes ... inflight gain tuning";
seed 000 Sec. VII: the operator's break-in, resume and "enough")."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Path, Query, Request
from fastapi.responses import JSONResponse

from companion.api_models import ParamAnswer, ParamSet  # the companion's own contract, proxied
from groundstation.companions import ApiError
from groundstation.schemas import (
    CommandAnswer,
    ErrorAnswer,
    MissionRequest,
    PauseRequest,
    StickLeaseOut,
    StickLeaseRequest,
    StickLeaseState,
    TakeRequest,
    VehicleList,
    VehicleOut,
    VehicleRegistration,
)
from groundstation.stick import Lease, StickLeases, desk_of
from mission_specs.param_table import ParamSpec, ParamWriteError, check_change, check_range, known

from . import audited, principal_of, service_of

router = APIRouter(tags=["vehicles"])
VehicleId = Annotated[int, Path(ge=1, le=255, description="the vehicle's MAVLink system id")]
ParamName = Annotated[str, Path(pattern=r"^[A-Z][A-Z0-9_]{0,15}$", description="e.g. ATC_RAT_RLL_P")]


def _vehicle(request: Request, vid: int) -> dict[str, Any]:
    for v in service_of(request).fleet.snapshot():
        if v["id"] == vid:
            return v
    raise ApiError(404, f"no vehicle {vid}")


@router.get("/vehicles", response_model=VehicleList)
def list_vehicles(request: Request) -> Any:
    """Every vehicle registered or heard on the team link, with its health."""
    # the records are built to the VehicleOut schema (fleet.py); answered as they are (a 100-vehicle
    # fleet's re-validation would dominate the answer's latency)
    return JSONResponse({"vehicles": service_of(request).fleet.snapshot()})


@router.get("/vehicles/{vid}", response_model=VehicleOut)
def get_vehicle(request: Request, vid: VehicleId) -> Any:
    return _vehicle(request, vid)


@router.put("/vehicles/{vid}", response_model=VehicleOut)
def register_vehicle(request: Request, vid: VehicleId, body: VehicleRegistration) -> Any:
    """Register a vehicle: its name and its companion's control URL (stored)."""
    def run() -> Any:
        service_of(request).register(vid, body.name, body.control_url)
        return _vehicle(request, vid)
    return audited(request, "register", f"vehicle {vid}", body.model_dump(), run)


def _checked(answer: dict[str, Any]) -> dict[str, Any]:
    if not answer["ok"]:
        extra = {}
        if isinstance(answer["answer"], dict) and answer["answer"].get("reasons"):
            extra["reasons"] = answer["answer"]["reasons"]
        status = answer["status"] if answer["status"] in (400, 404, 409, 422) else 409
        what = f"vehicle {answer['vehicle']}: {answer['command']}"
        raise ApiError(status, f"{what}: {answer['error']}", **extra)
    return answer


def _verb(request: Request, vid: int, verb: str, body: Any = None) -> Any:
    svc = service_of(request)
    return audited(request, verb, f"vehicle {vid}", body, lambda: _checked(svc.command(vid, verb, body)))


@router.post("/vehicles/{vid}/mission", response_model=CommandAnswer,
             responses={422: {"description": "rejected by delegation, with the reasons"}})
def give_mission(request: Request, vid: VehicleId, body: MissionRequest) -> Any:
    """A Task Specification Tree for one vehicle (delegation's reasons on rejection); the vehicle leaves
    the team (a directed command)."""
    svc = service_of(request)
    return audited(request, "mission", f"vehicle {vid}", body.model_dump(),
                   lambda: svc.give_mission(vid, body))


@router.get("/vehicles/{vid}/mission")
def get_mission(request: Request, vid: VehicleId) -> dict[str, Any]:
    """The vehicle's mission tree with each node's status and progress (seed 000 Fig. 5)."""
    status, answer = service_of(request).call(vid, "GET", "/mission")
    if status != 200:
        raise ApiError(409, f"vehicle {vid}: {answer}")
    return answer


@router.post("/vehicles/{vid}/start", response_model=CommandAnswer)
def start(request: Request, vid: VehicleId) -> Any:
    return _verb(request, vid, "start")


@router.post("/vehicles/{vid}/take", response_model=CommandAnswer)
def take(request: Request, vid: VehicleId, body: Annotated[TakeRequest | None, Body()] = None) -> Any:
    """Out of the team (the team re-allocates its tasks)."""
    return _verb(request, vid, "take", (body or TakeRequest()).model_dump())


@router.post("/vehicles/{vid}/release", response_model=CommandAnswer)
def release(request: Request, vid: VehicleId) -> Any:
    return _verb(request, vid, "release")


@router.post("/vehicles/{vid}/pause", response_model=CommandAnswer)
def pause(request: Request, vid: VehicleId, body: Annotated[PauseRequest | None, Body()] = None) -> Any:
    """The operator's break-in (seed 000 Sec. VII); joystick by default: the stick samples then come on
    the WebSocket."""
    return _verb(request, vid, "pause", (body or PauseRequest()).model_dump())


@router.post("/vehicles/{vid}/resume", response_model=CommandAnswer)
def resume(request: Request, vid: VehicleId) -> Any:
    return _verb(request, vid, "resume")


@router.post("/vehicles/{vid}/enough", response_model=CommandAnswer)
def enough(request: Request, vid: VehicleId) -> Any:
    """End the running task as done; the mission goes on (seed 000 Sec. VII)."""
    return _verb(request, vid, "enough")


@router.post("/vehicles/{vid}/user_confirm", response_model=CommandAnswer)
def user_confirm(request: Request, vid: VehicleId) -> Any:
    return _verb(request, vid, "user_confirm")


@router.post("/vehicles/{vid}/abort", response_model=CommandAnswer)
def abort(request: Request, vid: VehicleId) -> Any:
    return _verb(request, vid, "abort")


@router.post("/vehicles/{vid}/land", response_model=CommandAnswer)
def land(request: Request, vid: VehicleId) -> Any:
    return _verb(request, vid, "land")


@router.post("/vehicles/{vid}/rtl", response_model=CommandAnswer)
def rtl(request: Request, vid: VehicleId) -> Any:
    """Return home and land (the companion's RTL behavior, as the operator); an ``rtl`` event records it."""
    svc = service_of(request)
    try:
        answer = _verb(request, vid, "rtl")
    except ApiError as exc:
        svc.emit("rtl", f"vehicle {vid}: RTL refused: {exc.message}", severity="warning", vehicle=vid)
        raise
    reply = answer["answer"] if isinstance(answer["answer"], dict) else {}
    svc.emit("rtl", f"vehicle {vid}: RTL", vehicle=vid, data={"activation_id": reply.get("activation_id")})
    return answer


@router.get("/vehicles/{vid}/processes", response_model=list[dict[str, Any]])
def processes(request: Request, vid: VehicleId) -> Any:
    """The vehicle's processes (seed 003: the Process Monitor "displays the status of individual software
    processes running on each UAV")."""
    status, answer = service_of(request).call(vid, "GET", "/processes")
    if status != 200 or not isinstance(answer, list):
        raise ApiError(409, f"vehicle {vid}: no process list: {answer}")
    return answer


def _param(request: Request, vid: int, method: str, name: str, body: Any = None) -> dict[str, Any]:
    status, answer = service_of(request).call(vid, method, f"/params/{name}", body)
    if status != 200:
        err = answer.get("error") if isinstance(answer, dict) else answer
        raise ApiError(504 if status == 504 else 400 if status == 400 else 409, f"vehicle {vid}: {err}")
    return answer


@router.get("/vehicles/{vid}/params/{name}", response_model=ParamAnswer)
def get_param(request: Request, vid: VehicleId, name: ParamName) -> Any:
    return _param(request, vid, "GET", name)


def _param_spec(name: str, current: dict[str, Any]) -> ParamSpec:
    """The range to check: the vehicle's own table as its companion reported it, else the widest range
    of the bundled tables (the companion then applies its own)."""
    if current.get("autopilot") and current.get("min") is not None and current.get("max") is not None:
        return ParamSpec(name, float(current["min"]), float(current["max"]), current.get("units") or "")
    specs = known(name)
    return ParamSpec(name, min(s.min for s in specs), max(s.max for s in specs))


@router.put("/vehicles/{vid}/params/{name}", response_model=ParamAnswer,
            responses={400: {"model": ErrorAnswer, "description": "refused (the field named): a name "
                             "outside the tables of tunable parameters, an empty, non-numeric or "
                             "out-of-range value, more than 50 % of a change in flight without force"}})
def put_param(request: Request, vid: VehicleId, name: ParamName, body: ParamSet) -> Any:
    """In-flight gain tuning, guarded (:mod:`mission_specs.param_table`): only a parameter of the
    bundled tables, inside its range; while the vehicle is armed (or its state unknown) at most a 50 %
    change of the value read first unless ``force`` (operators only: observers cannot write). The answer
    is the autopilot's read-back; the audit log records the old and the new value."""
    record: dict[str, Any] = {"value": body.value, "force": body.force, "old": None}

    def run() -> dict[str, Any]:
        if not known(name):
            raise ApiError(400, f"name: {name} is not in the tables of tunable parameters")
        current = _param(request, vid, "GET", name)
        old = float(current["value"])
        record["old"] = old
        spec = _param_spec(name, current)
        armed = _vehicle(request, vid).get("armed")
        try:
            check_range(spec, body.value)
            if armed is not False and not body.force:
                check_change(spec, old, body.value)
        except ParamWriteError as exc:
            raise ApiError(400, str(exc)) from None
        answer = _param(request, vid, "PUT", name, {"value": body.value, "force": body.force})
        record["read_back"] = answer.get("value")
        return {**answer, "old": old}
    return audited(request, "param", f"vehicle {vid} {name}", record, run)


# --- the stick lease (groundstation.stick): one operator flies a vehicle's stick at a time ------------------
def _leases(request: Request) -> StickLeases:
    return desk_of(request.app.state, service_of(request).client).leases


def _lease_out(leases: StickLeases, lease: Lease) -> dict[str, Any]:
    return {"vehicle": lease.vehicle, "lease_id": lease.lease_id, "holder": lease.holder,
            "expires_in": leases.ttl_s, "ttl_s": leases.ttl_s}


@router.get("/vehicles/{vid}/stick/lease", response_model=StickLeaseState)
def get_stick_lease(request: Request, vid: VehicleId) -> Any:
    """Who holds the vehicle's stick (null: nobody)."""
    _vehicle(request, vid)
    return {"vehicle": vid, "stick_lease": _leases(request).view(vid)}


@router.post("/vehicles/{vid}/stick/lease", response_model=StickLeaseOut,
             responses={409: {"description": "another operator holds the stick, or the lease lapsed"}})
def take_stick_lease(request: Request, vid: VehicleId,
                     body: Annotated[StickLeaseRequest | None, Body()] = None) -> Any:
    """Take the vehicle's stick (no ``lease_id``), or keep a lease alive (its ``lease_id``). The joystick
    samples on the WebSocket carry the lease id; they renew it too. It lapses a few seconds after the last
    sample or keepalive; every page sees who holds it (the snapshot's ``stick_lease``)."""
    _vehicle(request, vid)
    leases, who = _leases(request), principal_of(request)
    if body is not None and body.lease_id is not None:
        return _lease_out(leases, leases.renew(vid, body.lease_id, who.name))

    return audited(request, "stick_lease", f"vehicle {vid}", None,
                   lambda: _lease_out(leases, leases.take(vid, who.name)))


@router.delete("/vehicles/{vid}/stick/lease", response_model=StickLeaseState,
               responses={409: {"description": "the lease is another operator's"}})
def release_stick_lease(request: Request, vid: VehicleId,
                        lease_id: Annotated[str, Query(min_length=1, max_length=64,
                                                       description="the lease to release")]) -> Any:
    """Let go of the vehicle's stick (samples stop: the vehicle stops within their validity)."""
    _vehicle(request, vid)
    leases, who = _leases(request), principal_of(request)

    def run() -> dict[str, Any]:
        released = leases.release(vid, lease_id, who.name)
        return {"vehicle": vid, "stick_lease": leases.view(vid), "released": released}
    return audited(request, "stick_release", f"vehicle {vid}", {"lease_id": lease_id}, run)
