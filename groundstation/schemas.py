"""The ground service's request and answer models: the OpenAPI document.

Positions are ``[lat, lon]`` or ``[lat, lon, alt]`` (degrees, metres above the vehicles' home), the
frame the operator gives team tasks in (seed 003 Sec. II). Every refusal answers :class:`ErrorAnswer`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from taskflight_common.geo import check_point

Point = list[float]
TASK_TYPES = ("visit", "patrol_line", "border_patrol", "area_scan", "tst")
COMMANDS = ("start", "take", "release", "pause", "resume", "enough", "user_confirm", "abort", "land")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


# --- errors ------------------------------------------------------------------------------------------
class ErrorAnswer(BaseModel):
    """Every refusal; nothing changed."""

    error: str
    reasons: list[str] | None = Field(None, description="the companion's delegation reasons (422)")
    offer: int | None = Field(None, description="409 on a divided task: the smaller N offered")
    free: int | None = Field(None, description="409 on a divided task: the vehicles free now")


# --- team tasks ----------------------------------------------------------------------------------------
class TaskRequest(_Strict):
    """A team task (seed 003 Sec. II). ``visit``: ``point``; ``patrol_line`` and ``border_patrol``:
    ``points`` (a polyline); ``area_scan``: ``area`` (a polygon); ``tst``: ``tree``. ``vehicles``: the N
    of a border patrol or area scan; more than are free answers 409 with the offer of a smaller N, which
    is accepted by asking again with ``vehicles`` = the offer or with ``accept_smaller``; ``force`` keeps
    N (the pieces wait for vehicles)."""

    type: Literal["visit", "patrol_line", "border_patrol", "area_scan", "tst"]
    point: Point | None = None
    points: list[Point] | None = Field(None, max_length=500)
    area: list[Point] | None = Field(None, max_length=500)
    tree: dict[str, Any] | None = None
    vehicles: int = Field(1, ge=1, le=64)
    altitude: float = Field(0.0, ge=0.0, le=1000.0, allow_inf_nan=False)
    speed: float = Field(0.0, ge=0.0, le=50.0, allow_inf_nan=False)
    name: str = Field("", max_length=100)
    accept_smaller: bool = False
    force: bool = False

    @field_validator("point")
    @classmethod
    def _point(cls, p: Point | None) -> Point | None:
        return None if p is None else check_point(p)

    @field_validator("points", "area")
    @classmethod
    def _points(cls, pts: list[Point] | None) -> list[Point] | None:
        if pts is not None:
            for i, p in enumerate(pts):
                check_point(p, f"[{i}]")
        return pts

    @model_validator(mode="after")
    def _shape(self) -> TaskRequest:
        need = {"visit": "point", "patrol_line": "points", "border_patrol": "points", "area_scan": "area",
                "tst": "tree"}[self.type]
        if getattr(self, need) is None:
            raise ValueError(f"{need}: a {self.type} task needs '{need}'")
        for other in ("point", "points", "area", "tree"):
            if other != need and getattr(self, other) is not None:
                raise ValueError(f"{other}: not a field of a {self.type} task (give '{need}')")
        if self.vehicles != 1 and self.type not in ("border_patrol", "area_scan"):
            raise ValueError(f"vehicles: only a border_patrol or area_scan is divided, not a {self.type}")
        return self


class TaskOut(BaseModel):
    id: int
    group: int = Field(description="the operator's divided task this is a piece of (0: none)")
    kind: str
    state: str = Field(description="unassigned, assigned, active, done, cancelled; held: restored from an "
                                   "earlier run and kept from the team until the operator releases it")
    holder: int | None = Field(description="the vehicle holding it (the assignee)")
    cost: float | None = Field(description="the holder's cost (s of flight)")
    version: int
    name: str
    points: list[Point]


class TaskAdded(BaseModel):
    ids: list[int] = Field(description="the allocatable tasks added (the pieces of a divided task)")
    group: int = Field(description="the divided task's id, to cancel all its pieces (0: not divided)")
    vehicles: int = Field(description="the N used")
    free: int = Field(description="the vehicles free when it was added")
    tasks: list[TaskOut]


class TaskList(BaseModel):
    tasks: list[TaskOut]


class TaskCancelled(BaseModel):
    cancelled: list[int]


# --- vehicles --------------------------------------------------------------------------------------------
class Position(BaseModel):
    lat: float
    lon: float
    alt: float = Field(description="m above home")


class Health(BaseModel):
    level: Literal["green", "yellow", "red"]
    reasons: list[str]


class MissionState(BaseModel):
    state: str | None = None
    node: str | None = Field(None, description="the active node")
    progress: str | None = None


class VehicleOut(BaseModel):
    id: int
    name: str
    control_url: str | None
    position: Position | None
    velocity: list[float] | None = Field(description="north, east, down m/s")
    heading: float | None = Field(description="degrees from north")
    mode: str | None
    armed: bool | None
    battery: float | None = Field(description="remaining, %")
    battery_voltage: float | None
    age_s: float | None = Field(description="age of the last message heard (team link or companion)")
    team_state: Literal["available", "taken", "gone", "unknown"]
    member_status: str | None = Field(description="idle, busy, taken, overridden, landed")
    task: int | None = Field(description="the team task flown")
    claims: list[dict[str, Any]]
    mission: MissionState
    queue_status: str | None
    confirmation_required: bool
    companion: Literal["ok", "unreachable", "none"]
    health: Health


class VehicleList(BaseModel):
    vehicles: list[VehicleOut]


class VehicleRegistration(_Strict):
    name: str = Field("", max_length=100)
    control_url: str | None = Field(None, max_length=300, pattern=r"^https?://[A-Za-z0-9.\-\[\]:]+(:\d+)?/?$",
                                    description="the companion's control surface, e.g. http://10.0.0.2:8765")


class MissionRequest(_Strict):
    """A Task Specification Tree (seed 000 Sec. III), the YAML format's structure as JSON."""

    mission: str = Field(..., min_length=1, max_length=100)
    description: str = Field("", max_length=1000)
    tree: dict[str, Any]
    start: bool = Field(False, description="start it at once when accepted")
    break_in: Literal["joystick", "hover"] = "joystick"


class PauseRequest(_Strict):
    routine_id: Literal["joystick", "hover"] = "joystick"


class TakeRequest(_Strict):
    reason: str = Field(default="operator", max_length=200)


class CommandAnswer(BaseModel):
    """One vehicle's answer to a command: the companion's answer (``status``: its HTTP status)."""

    vehicle: int
    command: str
    ok: bool
    status: int
    answer: Any = None
    error: str | None = None


class MultiCommand(_Strict):
    command: Literal["start", "take", "release", "pause", "resume", "enough", "user_confirm", "abort", "land",
                     "rtl"]
    vehicles: list[int] = Field(..., min_length=1, max_length=256)


class MultiCommandAnswer(BaseModel):
    results: list[CommandAnswer]


class EventOut(BaseModel):
    id: int
    t: float
    kind: str
    severity: str
    vehicle: int | None
    task: int | None
    message: str
    data: dict[str, Any]
    acked_by: str | None = Field(None, description="the operator who acknowledged it (alerts)")
    acked_at: float | None = None


class EventList(BaseModel):
    events: list[EventOut]
    last_id: int


class AlertList(BaseModel):
    alerts: list[EventOut] = Field(description="the newest alerts, oldest first")
    kinds: list[str] = Field(description="the event kinds that are alerts")


class TrackPoint(BaseModel):
    t: float
    lat: float | None
    lon: float | None
    alt: float | None
    heading: float | None
    mode: str | None
    armed: bool | None
    battery: float | None
    health: str | None


class TrackOut(BaseModel):
    vehicle: int
    since: float
    until: float
    points: list[TrackPoint] = Field(description="about 1 Hz, oldest first")


class ReleaseRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    ids: list[Annotated[int, Field(ge=1, le=10**9)]] | None = Field(
        None, max_length=10000, description="the held tasks to release (absent: every held task)")


class TasksReleased(BaseModel):
    released: list[int]
    held: list[int] = Field(description="the tasks still held")


class AuditOut(BaseModel):
    id: int
    t: float
    who: str
    role: str
    action: str
    target: str
    body: Any
    status: int
    answer: Any


class AuditList(BaseModel):
    entries: list[AuditOut]


class AssignmentOut(BaseModel):
    id: int
    t: float
    task: int
    state: str
    holder: int | None


class AssignmentList(BaseModel):
    assignments: list[AssignmentOut]


class MissionRecord(BaseModel):
    id: int
    t: float
    vehicle: int
    mission: Any
    status: int
    answer: Any


class MissionList(BaseModel):
    missions: list[MissionRecord]


class WhoAmI(BaseModel):
    role: str
    name: str


class FenceOut(BaseModel):
    """The operational fence the station refuses tasks outside of (``taskflight ground --fence``)."""

    points: list[Point] | None = Field(description="[lat, lon] vertices, or null without a fence")


# --- the stick lease ---------------------------------------------------------------------------------
class StickLeaseView(BaseModel):
    """Who holds a vehicle's stick (what every page sees)."""

    holder: str = Field(description="the holding operator's token name (role and fingerprint)")
    expires_in: float = Field(description="s until the lease lapses unless a sample or keepalive renews it")


class StickLeaseRequest(_Strict):
    """Take the stick (no body, or no ``lease_id``) or keep a lease alive (its ``lease_id``)."""

    lease_id: str | None = Field(None, min_length=1, max_length=64,
                                 description="the lease to renew (a keepalive); left out: take a new one")


class StickLeaseOut(BaseModel):
    """A lease taken or renewed: send its ``lease_id`` with each stick sample on the WebSocket."""

    vehicle: int
    lease_id: str
    holder: str
    expires_in: float
    ttl_s: float = Field(description="how long a lease lives after its last sample or keepalive (s)")


class StickLeaseState(BaseModel):
    vehicle: int
    stick_lease: StickLeaseView | None = Field(description="null: nobody holds the stick")
    released: bool | None = Field(None, description="DELETE: false when the lease had already lapsed")
