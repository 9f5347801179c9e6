"""Mission plan items of the autopilot model: the commands, frames and mission types the model accepts,
:class:`MissionItem` (the fields of MISSION_ITEM_INT), the checks of one item and of a whole plan
(:func:`validate_item`, :func:`validate_plan`) and the geodesy that places an item in the local frame
(:func:`item_to_ned`, :func:`vehicle_frames`). Storage is :mod:`.mission_store`, execution :mod:`.mission`
(which re-exports these names).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from taskflight_common.geo import geodetic_to_ned

if TYPE_CHECKING:
    from autopilot_model.modules.vehicle_api import VehicleApi

MISSION = mavlink.MAV_MISSION_TYPE_MISSION
FENCE = mavlink.MAV_MISSION_TYPE_FENCE
RALLY = mavlink.MAV_MISSION_TYPE_RALLY
MISSION_TYPES = (MISSION, FENCE, RALLY)
MAX_ITEMS = 724
"""Largest plan accepted (ArduPilot's mission storage on a typical board holds about this many)."""

# --- commands and frames the model understands ----------------------------------------------------
NAV_WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
NAV_LOITER_TIME = mavlink.MAV_CMD_NAV_LOITER_TIME
NAV_RETURN_TO_LAUNCH = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
NAV_LAND = mavlink.MAV_CMD_NAV_LAND
NAV_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
DO_CHANGE_SPEED = mavlink.MAV_CMD_DO_CHANGE_SPEED
FENCE_RETURN_POINT = mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT
FENCE_POLYGON_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
FENCE_POLYGON_EXCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
FENCE_CIRCLE_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
FENCE_CIRCLE_EXCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
RALLY_POINT = mavlink.MAV_CMD_NAV_RALLY_POINT
NAV_LOITER_UNLIM = mavlink.MAV_CMD_NAV_LOITER_UNLIM
NAV_LOITER_TURNS = mavlink.MAV_CMD_NAV_LOITER_TURNS
DO_JUMP = mavlink.MAV_CMD_DO_JUMP
CONDITION_DELAY = mavlink.MAV_CMD_CONDITION_DELAY
CONDITION_YAW = mavlink.MAV_CMD_CONDITION_YAW
DO_SET_ROI = mavlink.MAV_CMD_DO_SET_ROI
DO_SET_ROI_LOCATION = mavlink.MAV_CMD_DO_SET_ROI_LOCATION
DO_SET_ROI_NONE = mavlink.MAV_CMD_DO_SET_ROI_NONE

NAV_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH, NAV_LAND, NAV_TAKEOFF,
                          NAV_LOITER_UNLIM, NAV_LOITER_TURNS})
"""Navigation commands: they move the vehicle and need a position (except RTL)."""
DO_COMMANDS = frozenset({DO_CHANGE_SPEED, DO_JUMP, CONDITION_DELAY, CONDITION_YAW, DO_SET_ROI,
                         DO_SET_ROI_LOCATION, DO_SET_ROI_NONE})
""""Do" and "condition" commands: run beside the navigation command they follow (AP_Mission)."""
POSITIONLESS = frozenset({NAV_RETURN_TO_LAUNCH, DO_CHANGE_SPEED, DO_JUMP, CONDITION_DELAY, CONDITION_YAW,
                          DO_SET_ROI_NONE})
"""Commands whose x/y/z are unused (any frame accepted, as ArduPilot does)."""
SUPPORTED: dict[int, frozenset[int]] = {
    MISSION: NAV_COMMANDS | DO_COMMANDS,
    FENCE: frozenset({FENCE_RETURN_POINT, FENCE_POLYGON_INCLUSION, FENCE_POLYGON_EXCLUSION,
                      FENCE_CIRCLE_INCLUSION, FENCE_CIRCLE_EXCLUSION}),
    RALLY: frozenset({RALLY_POINT}),
}

FRAME_GLOBAL = mavlink.MAV_FRAME_GLOBAL
FRAME_GLOBAL_INT = mavlink.MAV_FRAME_GLOBAL_INT
FRAME_RELATIVE = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
FRAME_RELATIVE_INT = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
GLOBAL_FRAMES = frozenset({FRAME_GLOBAL, FRAME_GLOBAL_INT, FRAME_RELATIVE, FRAME_RELATIVE_INT})
RELATIVE_FRAMES = frozenset({FRAME_RELATIVE, FRAME_RELATIVE_INT})

_PARAM_ERRORS = (mavlink.MAV_MISSION_INVALID_PARAM1, mavlink.MAV_MISSION_INVALID_PARAM2,
                 mavlink.MAV_MISSION_INVALID_PARAM3, mavlink.MAV_MISSION_INVALID_PARAM4)
ACCEPTED = mavlink.MAV_MISSION_ACCEPTED


@dataclass(frozen=True)
class MissionItem:
    """One plan item with the fields of MISSION_ITEM_INT (x, y: degrees * 1e7 in global frames)."""

    seq: int
    frame: int
    command: int
    current: int = 0
    autocontinue: int = 1
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    mission_type: int = MISSION

    @property
    def lat(self) -> float:
        return self.x * 1e-7

    @property
    def lon(self) -> float:
        return self.y * 1e-7

    @classmethod
    def from_msg(cls, msg: Any) -> MissionItem:
        """From a MISSION_ITEM_INT, or from a legacy MISSION_ITEM (x, y in degrees, float).

        Raises :class:`ValueError` with a MAV_MISSION_RESULT code as ``args[1]`` if the legacy
        position cannot be converted.
        """
        x, y = msg.x, msg.y
        if msg.get_type() == "MISSION_ITEM":
            scale = 1e7 if msg.frame in GLOBAL_FRAMES else 1.0
            x, y = _legacy_coord(x, scale, msg.command, mavlink.MAV_MISSION_INVALID_PARAM5_X), \
                _legacy_coord(y, scale, msg.command, mavlink.MAV_MISSION_INVALID_PARAM6_Y)
        return cls(seq=int(msg.seq), frame=int(msg.frame), command=int(msg.command),
                   current=int(msg.current), autocontinue=int(msg.autocontinue),
                   param1=float(msg.param1), param2=float(msg.param2), param3=float(msg.param3),
                   param4=float(msg.param4), x=int(x), y=int(y), z=float(msg.z),
                   mission_type=int(getattr(msg, "mission_type", MISSION) or 0))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> MissionItem:
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


def _legacy_coord(value: float, scale: float, command: int, error: int) -> int:
    if not math.isfinite(value):
        if command in POSITIONLESS or command == DO_CHANGE_SPEED:
            return 0
        raise ValueError("non-finite coordinate", error)
    scaled = round(value * scale)
    if abs(scaled) > 2**31 - 1:
        raise ValueError("coordinate out of range", error)
    return scaled


# --- validation -------------------------------------------------------------------------------------
def validate_item(item: MissionItem) -> int:
    """Check one item against what the model can fly; returns a MAV_MISSION_RESULT (ACCEPTED if fine).

    NaN is accepted in param1-4 where MAVLink uses it for "default / no change" (e.g. yaw), and
    treated as 0 when flown; infinities never are. Positions must be finite and in range.
    """
    if item.mission_type not in SUPPORTED:
        return mavlink.MAV_MISSION_UNSUPPORTED
    if item.command not in SUPPORTED[item.mission_type]:
        return mavlink.MAV_MISSION_UNSUPPORTED
    params = (item.param1, item.param2, item.param3, item.param4)
    for p, err in zip(params, _PARAM_ERRORS, strict=True):
        if math.isinf(p):
            return err
    if item.command in POSITIONLESS:
        return ACCEPTED
    if item.frame not in GLOBAL_FRAMES:
        return mavlink.MAV_MISSION_UNSUPPORTED_FRAME
    if not -900_000_000 <= item.x <= 900_000_000:
        return mavlink.MAV_MISSION_INVALID_PARAM5_X
    if not -1_800_000_000 <= item.y <= 1_800_000_000:
        return mavlink.MAV_MISSION_INVALID_PARAM6_Y
    if not math.isfinite(item.z) and item.mission_type != FENCE:
        return mavlink.MAV_MISSION_INVALID_PARAM7
    c = item.command
    if c in (NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_TURNS) and item.param1 < 0:
        return mavlink.MAV_MISSION_INVALID_PARAM1  # hold / loiter time
    if c == NAV_WAYPOINT and item.param2 < 0:
        return mavlink.MAV_MISSION_INVALID_PARAM2  # acceptance radius
    if c in (FENCE_POLYGON_INCLUSION, FENCE_POLYGON_EXCLUSION) and not (
            math.isfinite(item.param1) and item.param1 >= 3 and item.param1 == int(item.param1)):
        return mavlink.MAV_MISSION_INVALID_PARAM1  # vertex count
    if c in (FENCE_CIRCLE_INCLUSION, FENCE_CIRCLE_EXCLUSION) and not (
            math.isfinite(item.param1) and item.param1 > 0):
        return mavlink.MAV_MISSION_INVALID_PARAM1  # radius
    return ACCEPTED


def validate_plan(mission_type: int, items: list[MissionItem]) -> int:
    """Whole-plan checks done when an upload completes: fence polygons must be whole; a DO_JUMP must
    name an item of the plan other than home (ArduPilot: MAV_MISSION_ERROR)."""
    if mission_type == MISSION:
        for it in items:
            if it.command == DO_JUMP and not (
                    math.isfinite(it.param1) and 1 <= int(it.param1) < len(items)):
                return mavlink.MAV_MISSION_ERROR
        return ACCEPTED
    if mission_type != FENCE:
        return ACCEPTED
    i = 0
    while i < len(items):
        it = items[i]
        if it.command in (FENCE_POLYGON_INCLUSION, FENCE_POLYGON_EXCLUSION):
            n = int(it.param1)
            group = items[i:i + n]
            if len(group) != n or any(g.command != it.command or int(g.param1) != n for g in group):
                return mavlink.MAV_MISSION_INVALID_PARAM1
            i += n
        else:
            i += 1
    return ACCEPTED



# --- geodesy ----------------------------------------------------------------------------------------
def item_to_ned(item: MissionItem, origin: tuple[float, float, float], home_alt: float,
                current_ned: tuple[float, float, float]) -> tuple[float, float, float]:
    """The item's position in local NED (m) relative to ``origin`` (lat, lon, alt AMSL).

    Relative-altitude frames are relative to ``home_alt`` (AMSL). As in ArduPilot, lat = lon = 0 means
    "here" (the current horizontal position) and, in relative frames, z = 0 means "this altitude".
    """
    alt0 = origin[2]
    if item.x == 0 and item.y == 0:
        n, e = current_ned[0], current_ned[1]
    else:
        n, e, _ = geodetic_to_ned(origin, item.lat, item.lon, alt0)
    if item.frame in RELATIVE_FRAMES:
        if item.z == 0:
            d = current_ned[2]
        else:
            d = -(item.z + home_alt - alt0)
    else:
        d = -(item.z - alt0)
    return float(n), float(e), float(d)



Vec3 = tuple[float, float, float]


def vehicle_frames(vehicle: VehicleApi) -> tuple[Vec3, float, Vec3]:
    """(origin (lat, lon, alt AMSL) of the local frame, home altitude AMSL, home position NED)."""
    o = vehicle.state.origin
    origin = (float(o[0]), float(o[1]), float(o[2]))
    lat, lon, alt = (float(x) for x in vehicle.home[:3])
    n, e, d = geodetic_to_ned(origin, lat, lon, alt)
    return origin, alt, (float(n), float(e), float(d))
