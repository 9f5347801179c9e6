"""Missions of the autopilot model: the stored plans (:class:`MissionStore`), what the model accepts in
them (:func:`validate_item`, :func:`validate_plan`) and AUTO-mode execution (:class:`MissionRunner`).

Items keep the fields of MAVLink's MISSION_ITEM_INT so that a download returns exactly what was
uploaded. As in ArduPilot, item 0 of the flight plan (mission type MISSION) is home: it is stored
and returned but never flown; AUTO starts at item 1. Fence and rally plans are stored the same way
(fence polygons and circles are read by :mod:`autopilot_model.modules.safety`).
"""

from __future__ import annotations

import json
import logging
import math
import os
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import pymap3d
from pymavlink.dialects.v20 import ardupilotmega as mavlink

log = logging.getLogger(__name__)

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

NAV_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH, NAV_LAND, NAV_TAKEOFF})
"""Navigation commands: they move the vehicle and need a position (except RTL)."""
POSITIONLESS = frozenset({NAV_RETURN_TO_LAUNCH, DO_CHANGE_SPEED})
"""Commands whose x/y/z are unused (any frame accepted, as ArduPilot does)."""
SUPPORTED: dict[int, frozenset[int]] = {
    MISSION: NAV_COMMANDS | {DO_CHANGE_SPEED},
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
    if c in (NAV_WAYPOINT, NAV_LOITER_TIME) and item.param1 < 0:
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
    """Whole-plan checks done when an upload completes (fence polygons must be whole)."""
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


# --- storage ----------------------------------------------------------------------------------------
class MissionStore:
    """The stored plans, one list per mission type, and the current flight-plan item.

    ``replace`` swaps a whole plan at once (the protocol uploads into a staging list and calls it only
    when the upload succeeded), so a failed upload never leaves a half-written plan. With a path, the
    plans are loaded from it and every change is written back (atomically), one file per instance.
    """

    def __init__(self, path: str | Path | None = None) -> None:
        self._plans: dict[int, list[MissionItem]] = {t: [] for t in MISSION_TYPES}
        self.current = 0
        self.running = False
        """True while AUTO executes the flight plan (set by :class:`MissionRunner`)."""
        self._listeners: list[Callable[[int], None]] = []
        self._current_listeners: list[Callable[[int], None]] = []
        self._path = Path(path) if path is not None else None
        if self._path is not None:
            self._load()

    # --- reading --------------------------------------------------------------------------------
    @property
    def items(self) -> list[MissionItem]:
        """The flight plan (mission type MISSION), item 0 being home."""
        return list(self._plans[MISSION])

    def get(self, mission_type: int = MISSION) -> list[MissionItem]:
        return list(self._plans[mission_type])

    def count(self, mission_type: int = MISSION) -> int:
        return len(self._plans[mission_type])

    def item(self, seq: int, mission_type: int = MISSION) -> MissionItem:
        return self._plans[mission_type][seq]

    # --- writing --------------------------------------------------------------------------------
    def replace(self, mission_type: int, items: Iterable[MissionItem]) -> None:
        """Swap in a whole plan (seq renumbered 0..n-1, mission_type set) and persist it."""
        new = [replace(it, seq=i, mission_type=mission_type) for i, it in enumerate(items)]
        self._plans[mission_type] = new
        if mission_type == MISSION and self.current >= len(new):
            self.current = 0
        log.info("stored %d item(s) of mission type %d", len(new), mission_type)
        self._save()
        for cb in list(self._listeners):
            cb(mission_type)

    def clear(self, mission_type: int) -> None:
        self.replace(mission_type, [])

    def set_current(self, seq: int) -> bool:
        """Make ``seq`` the current flight-plan item; False (unchanged) if out of range."""
        if not 0 <= seq < self.count(MISSION):
            return False
        if seq != self.current:
            self.current = seq
            self._save()
            for cb in list(self._current_listeners):
                cb(seq)
        return True

    def on_change(self, callback: Callable[[int], None]) -> None:
        """Call ``callback(mission_type)`` after a plan is replaced or cleared."""
        self._listeners.append(callback)

    def on_current(self, callback: Callable[[int], None]) -> None:
        """Call ``callback(seq)`` when the current item changes."""
        self._current_listeners.append(callback)

    # --- persistence ----------------------------------------------------------------------------
    def _load(self) -> None:
        assert self._path is not None
        if not self._path.exists():
            return
        try:
            data = json.loads(self._path.read_text(encoding="utf-8"))
            plans = {int(t): [MissionItem.from_dict(d) for d in items]
                     for t, items in data.get("plans", {}).items() if int(t) in MISSION_TYPES}
            current = int(data.get("current", 0))
        except (OSError, ValueError, TypeError, AttributeError) as exc:
            log.warning("ignoring unreadable mission file %s: %s", self._path, exc)
            return
        for t, items in plans.items():
            bad = next((r for r in (validate_item(i) for i in items) if r != ACCEPTED), ACCEPTED)
            if bad != ACCEPTED or validate_plan(t, items) != ACCEPTED:
                log.warning("%s: stored plan of type %d is invalid (%d); dropped", self._path, t, bad)
                continue
            self._plans[t] = items
        self.current = current if 0 <= current < max(1, len(self._plans[MISSION])) else 0

    def _save(self) -> None:
        if self._path is None:
            return
        data = {"version": 1, "current": self.current,
                "plans": {str(t): [i.to_dict() for i in items] for t, items in self._plans.items()}}
        self._path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self._path.with_suffix(".tmp")
        tmp.write_text(json.dumps(data, indent=1), encoding="utf-8")
        os.replace(tmp, self._path)


# --- geodesy ----------------------------------------------------------------------------------------
def item_to_ned(item: MissionItem, origin: tuple[float, float, float], home_alt: float,
                current_ned: tuple[float, float, float]) -> tuple[float, float, float]:
    """The item's position in local NED (m) relative to ``origin`` (lat, lon, alt AMSL).

    Relative-altitude frames are relative to ``home_alt`` (AMSL). As in ArduPilot, lat = lon = 0 means
    "here" (the current horizontal position) and, in relative frames, z = 0 means "this altitude".
    """
    lat0, lon0, alt0 = origin
    if item.x == 0 and item.y == 0:
        n, e = current_ned[0], current_ned[1]
    else:
        n, e, _ = pymap3d.geodetic2ned(item.lat, item.lon, alt0, lat0, lon0, alt0)
    if item.frame in RELATIVE_FRAMES:
        if item.z == 0:
            d = current_ned[2]
        else:
            d = -(item.z + home_alt - alt0)
    else:
        d = -(item.z - alt0)
    return float(n), float(e), float(d)


def _finite(value: float, default: float = 0.0) -> float:
    return value if math.isfinite(value) else default
