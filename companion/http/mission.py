"""The mission layer on the control surface (seed 000 Sec. III, VII).

===============================  =====================================================================
``POST /mission``                a mission: JSON (``{"mission": name, "tree": {...}}``, the YAML format's
                                 structure) or YAML text (``Content-Type: application/yaml``); runs
                                 delegation -> ``{"accepted": true, "tree": ..., "delegation": ...}``;
                                 422 ``{"error", "reasons"}`` when the platform rejects it; 400 when
                                 malformed (the message names the line and field)
``POST /mission/start``          optional ``{"break_in": "joystick" | "hover"}`` (what a pause does)
``POST /mission/pause``          the operator's break-in: optional ``{"routine_id": "joystick" |
                                 "hover"}`` (default joystick: all channels from the operator's feed)
``POST /mission/continue``       resume where it stopped
``POST /mission/enough``         end the running task as done; the mission goes on with the next node
``POST /mission/abort``          abort the mission, then apply its ``on_failure`` policy (hover: the
                                 vehicle hovers, KEEP_HOVERING; land: LAND; rtl: RTL); optional
                                 ``{"on_failure": "hover" | "land" | "rtl"}`` for this abort
``POST /mission/resume``         fly the rest of a failed or aborted mission: optional ``{"node": id}``
                                 (default: the node that failed or was aborted), ``"take_off": true``
                                 (the vehicle is on the ground and the rest does not begin with a
                                 take-off); delegated again -> as ``POST /mission``, and started
``GET  /mission``                the expanded tree: each node's id, type, parameters, plan, Fig. 4 flags,
                                 Fig. 5 status and progress (e.g. "waypoint 4 of 12"), what a waiting
                                 node waits for (``waiting_for``), retries and attempt; the mission's
                                 ``readiness``, ``on_failure``, the ``failure_policy`` applied and the
                                 ``failed_node``
``GET  /mission/detections``     what the current (or last) mission's scans saw: each detection's node,
                                 data_uuid, time, object and position; with ``generate_scan_specs_flag``
                                 the scan's specs and a sub-area of interest per detection
                                 (:func:`detections_router`)
===============================  =====================================================================

A request the Fig. 4 flags or the mission's state forbid answers 409 with the reason. While the autopilot
is not ready (its link hears no heartbeat, no home, no healthy position estimate) ``POST /mission``,
``/mission/start`` and ``/mission/resume`` answer 503 with the reason and change nothing. What happened is
streamed by ``GET /mission/events`` (:mod:`companion.http.events`).
"""

from __future__ import annotations

import json
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field

from companion.mission_service import MissionService, NotReadyError
from companion.team.member import TeamMember
from companion.tst.resume import ResumeError
from companion.tst.spec import mission_from_dict, mission_from_yaml
from companion.tst.status import ExecutionRequestError, NodeExecutionStatus
from companion.tst.tree import TreeError
from taskflight_common.geo import ned_to_geodetic
from taskflight_common.httpapi import ApiError
from taskflight_common.yamlio import ConfigError

YAML_TYPES = ("application/yaml", "application/x-yaml", "text/yaml", "text/x-yaml")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class StartRequest(_Strict):
    break_in: str = Field(default="joystick", pattern="^(joystick|hover)$",
                          description="what a pause does: the operator's joystick, or hold")


class PauseMissionRequest(_Strict):
    routine_id: str = Field(default="joystick", pattern="^(joystick|hover)$")


class AbortRequest(_Strict):
    on_failure: str | None = Field(default=None, pattern="^(hover|land|rtl)$",
                                   description="what this abort does then (default: the mission's "
                                               "on_failure)")


class ResumeRequest(_Strict):
    node: str | None = Field(default=None, description="the node to fly again from (default: the one that "
                                                       "failed or was aborted)")
    take_off: bool = Field(default=False, description="take off first (the vehicle is on the ground)")
    break_in: str = Field(default="joystick", pattern="^(joystick|hover)$")


class MissionVerbResponse(BaseModel):
    ok: bool
    state: str
    status: dict[str, Any]


class MissionAccepted(BaseModel):
    accepted: bool
    tree: dict[str, Any] | None
    delegation: dict[str, Any]


def router(service: MissionService, team: TeamMember | None = None) -> APIRouter:
    """The routes above.

    With ``team`` (the vehicle's :class:`~companion.team.member.TeamMember`), a mission given here is a
    directed command of the process monitor (seed 003 Fig. 1): the vehicle leaves the team first.
    """
    app = APIRouter(tags=["mission"])
    app.include_router(detections_router(service))

    def directed() -> None:
        if team is not None:
            team.take("directed mission")

    def verb(fn: Any, *args: Any) -> MissionVerbResponse:
        try:
            st: NodeExecutionStatus = fn(*args)
        except NotReadyError as exc:
            raise ApiError(503, str(exc)) from None
        except ExecutionRequestError as exc:
            raise ApiError(409, str(exc)) from None
        return MissionVerbResponse(ok=True, state=st.state, status=st.to_dict())

    def answer(result: Any) -> Any:
        if not result.accepted:
            return JSONResponse(status_code=422, content={
                "error": "rejected: " + "; ".join(result.reasons), "reasons": result.reasons})
        return MissionAccepted(accepted=True, tree=service.status()["tree"], delegation=result.to_dict())

    @app.post("/mission", response_model=MissionAccepted,
              responses={422: {"description": "rejected by delegation: {error, reasons}"},
                         503: {"description": "the autopilot is not ready: {error}"}})
    async def submit(request: Request) -> Any:
        raw = (await request.body()).decode("utf-8", errors="replace")
        kind = request.headers.get("content-type", "").split(";")[0].strip().lower()
        try:
            if kind in YAML_TYPES:
                mission = mission_from_yaml(raw, "<request>")
            elif kind == "application/json":
                mission = mission_from_dict(json.loads(raw), "<request>")
            else:
                raise ApiError(415, f"send the mission as application/json or application/yaml, not {kind!r}")
        except json.JSONDecodeError as exc:
            raise ApiError(400, f"malformed JSON: {exc}") from None
        except (ConfigError, TreeError, ValueError) as exc:
            raise ApiError(400, str(exc)) from None
        why = service.readiness()
        if why is not None:  # before the team lets the vehicle go
            raise ApiError(503, f"mission refused: {why}")
        if team is not None:  # a refused mission leaves the vehicle on its team task
            checked = service.check(mission)
            if not checked.accepted:
                return answer(checked)
        directed()
        try:
            result = service.submit(mission)
        except NotReadyError as exc:
            raise ApiError(503, str(exc)) from None
        except ExecutionRequestError as exc:
            raise ApiError(409, str(exc)) from None
        return answer(result)

    @app.post("/mission/start", response_model=MissionVerbResponse,
              responses={503: {"description": "the autopilot is not ready: {error}"}})
    def start(body: StartRequest | None = None) -> MissionVerbResponse:
        why = service.readiness()
        if why is not None:
            raise ApiError(503, f"mission start refused: {why}")
        directed()
        return verb(service.start, (body or StartRequest()).break_in)

    @app.post("/mission/pause", response_model=MissionVerbResponse)
    def pause(body: PauseMissionRequest | None = None) -> MissionVerbResponse:
        return verb(service.pause, (body or PauseMissionRequest()).routine_id)

    @app.post("/mission/continue", response_model=MissionVerbResponse)
    def continue_() -> MissionVerbResponse:
        return verb(service.continue_)

    @app.post("/mission/enough", response_model=MissionVerbResponse)
    def enough() -> MissionVerbResponse:
        return verb(service.enough)

    @app.post("/mission/abort", response_model=MissionVerbResponse)
    def abort(body: AbortRequest | None = None) -> MissionVerbResponse:
        return verb(service.abort, "operator", (body or AbortRequest()).on_failure)

    @app.post("/mission/resume", response_model=MissionAccepted,
              responses={422: {"description": "the rest rejected by delegation: {error, reasons}"},
                         503: {"description": "the autopilot is not ready: {error}"}})
    def resume(body: ResumeRequest | None = None) -> Any:
        b = body or ResumeRequest()
        directed()
        try:
            result = service.resume(b.node, b.take_off, b.break_in)
        except NotReadyError as exc:
            raise ApiError(503, str(exc)) from None
        except ResumeError as exc:
            raise ApiError(400, str(exc)) from None
        except ExecutionRequestError as exc:
            raise ApiError(409, str(exc)) from None
        return answer(result)

    @app.get("/mission")
    def mission() -> dict[str, Any]:
        return service.status()

    return app


# --- what the scans saw ---------------------------------------------------------------------------------
class DetectionView(BaseModel):
    node: str = Field(description="the scan-ground node that was running")
    data_uuid: str | None = Field(description="the scan's label (Fig. 14a data_uuid)")
    t: float = Field(description="when the object came into view (s, the companion's clock)")
    object: int | str = Field(description="the object's id (as in the beliefs object(id, kind))")
    kind: str = Field(description="the object's class")
    position_ned: list[float] = Field(description="where the object is: north, east, down (m from home)")
    position: list[float] = Field(description="where the object is: lat, lon (degrees)")
    vehicle_neu: list[float] = Field(description="where the vehicle was: north, east, altitude (m)")


class ScanSpecsView(BaseModel):
    node: str
    data_uuid: str | None
    specs: dict[str, Any] = Field(description="the scan's pattern, footprint, expected duration (area scans)")
    areas_of_interest: list[dict[str, Any]] = Field(
        description="per detection: a sub-area centred on the object and the scan-ground node that scans it")


class DetectionsView(BaseModel):
    mission: str | None
    state: str
    detections: list[DetectionView]
    scan_specs: list[ScanSpecsView] = Field(
        description="one per scan with generate_scan_specs_flag that ended")


def detections_router(service: MissionService) -> APIRouter:
    """``GET /mission/detections``: the detections of the current (or last) mission's scan-ground nodes
    (seed 000 Fig. 14a: the data "labeled with [the data_uuid]"), and the scan specs those with
    ``generate_scan_specs_flag`` generated (Sec. VI-E: "a sub-area of interest to be subsequently
    scanned")."""
    app = APIRouter(tags=["mission"])

    @app.get("/mission/detections", response_model=DetectionsView)
    def detections() -> DetectionsView:
        status = service.status()
        home = service.platform().home
        origin = (float(home[0]), float(home[1]), 0.0)
        found: list[DetectionView] = []
        specs: list[ScanSpecsView] = []
        for run in list(service.execution.runs.values()):
            seen = getattr(run, "detections", None)
            if not callable(seen):
                continue  # not a scan
            node_id = str(run.node.id)
            uuid = run.node.params.get("data_uuid")
            for d in seen():
                lat, lon, _ = ned_to_geodetic(origin, *d.position)
                found.append(DetectionView(node=node_id, data_uuid=d.data_uuid, t=round(d.t_s, 3),
                                           object=d.object_id, kind=d.cls, position_ned=list(d.position),
                                           position=[round(lat, 8), round(lon, 8)],
                                           vehicle_neu=[round(v, 3) for v in d.vehicle]))
            generated = getattr(run, "scan_specs", None)
            if generated is not None:
                specs.append(ScanSpecsView(node=node_id, data_uuid=uuid, **generated))
        found.sort(key=lambda d: d.t)
        return DetectionsView(mission=status.get("mission"), state=str(status.get("state")),
                              detections=found, scan_specs=specs)

    return app
