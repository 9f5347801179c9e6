"""A mirror of the vehicle's state, written only by the link's receive thread (seed 003 one-writer rule).

Seed 000 Fig. 10: the QuadNode derives its topics from the platform's telemetry. The mirror folds
the autopilot's messages into one :class:`MirrorState` (position, velocity, attitude, mode, armed,
landed state, battery, sensors, home, GPS, the last POSITION_TARGET_LOCAL_NED echo, the downward
DISTANCE_SENSOR, STATUSTEXTs); readers
take an immutable :meth:`VehicleMirror.snapshot`. Units are MAVLink's SI units (m, m/s, rad);
positions are local NED from the EKF origin, as LOCAL_POSITION_NED reports them.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.flight.setpoint import VehicleState
from taskflight_common.ardupilot import COPTER_MODE_NAMES, CopterMode

M = mavlink
Vec3 = tuple[float, float, float]

LANDED_STATE_NAMES = {0: "UNDEFINED", 1: "ON_GROUND", 2: "IN_AIR", 3: "TAKEOFF", 4: "LANDING"}
#: ArduCopter custom_mode numbers -> names (the companion uses GUIDED and LAND; the rest for status).
COPTER_MODES = COPTER_MODE_NAMES
GUIDED = CopterMode.GUIDED
LAND = CopterMode.LAND


@dataclass(frozen=True)
class PositionTargetEcho:
    """The autopilot's POSITION_TARGET_LOCAL_NED: what it is following."""

    time_boot_ms: int
    type_mask: int
    p: Vec3
    v: Vec3


@dataclass(frozen=True)
class RcReport:
    """The autopilot's RC_CHANNELS: PWM microseconds per channel (0 / 65535 unused), RSSI (255 unknown)."""

    time_boot_ms: int
    channels: tuple[int, ...]
    rssi: int


@dataclass(frozen=True)
class RangeReport:
    """The autopilot's downward DISTANCE_SENSOR (orientation 25, MAV_SENSOR_ROTATION_PITCH_270).

    ``distance_m``, ``min_m``, ``max_m`` in metres (the message's centimetres); ``time_boot_ms`` the
    autopilot's time of the report; ``altitude_m`` the mirrored altitude (m up, -LOCAL_POSITION_NED z) when
    it arrived and ``cos_tilt`` the cosine of the vehicle's tilt then (cos roll x cos pitch, ATTITUDE), so
    ``ground_altitude`` = the ground under the vehicle in the local frame, the slant reading made vertical
    as ArduCopter's ``read_rangefinder`` does."""

    time_boot_ms: int
    distance_m: float
    min_m: float
    max_m: float
    altitude_m: float | None
    cos_tilt: float = 1.0

    @property
    def in_range(self) -> bool:
        """Inside the sensor's reliable distances (ArduPilot's status Good)."""
        return self.min_m <= self.distance_m <= self.max_m

    @property
    def ground_altitude(self) -> float | None:
        """The ground's altitude (m up in the local frame) under the vehicle, None when unknown."""
        if self.altitude_m is None or not self.in_range:
            return None
        return self.altitude_m - self.distance_m * self.cos_tilt


@dataclass(frozen=True)
class MirrorState:
    """One consistent view of the vehicle (None / 0 where not yet received)."""

    system_id: int | None = None
    component_id: int | None = None
    heartbeats: int = 0
    last_heartbeat_wall: float | None = None
    time_boot_ms: int | None = None
    mode: int | None = None
    base_mode: int = 0
    system_status: int = 0
    armed: bool = False
    landed_state: int = 0
    position: Vec3 | None = None
    position_time_ms: int | None = None  # LOCAL_POSITION_NED's time_boot_ms (the estimate's age)
    velocity: Vec3 = (0.0, 0.0, 0.0)
    attitude: Vec3 | None = None  # roll, pitch, yaw (rad)
    battery_voltage: float | None = None
    battery_remaining: int | None = None
    battery_current: float | None = None  # A (SYS_STATUS / BATTERY_STATUS current_battery; None unknown)
    battery_consumed_mah: float | None = None  # BATTERY_STATUS current_consumed (None unknown)
    sensors_present: int = 0  # SYS_STATUS onboard_control_sensors_present / _health (MAV_SYS_STATUS_*)
    sensors_health: int = 0
    home: tuple[float, float, float] | None = None  # lat, lon (deg), alt AMSL (m)
    gps_fix_type: int = 0
    gps_satellites: int = 0
    global_position: tuple[float, float, float, float] | None = None  # lat, lon, alt AMSL, rel. alt
    position_target: PositionTargetEcho | None = None
    rc: RcReport | None = None
    range_down: RangeReport | None = None
    messages: int = 0
    texts: tuple[str, ...] = field(default_factory=tuple)

    @property
    def mode_name(self) -> str | None:
        return None if self.mode is None else COPTER_MODES.get(self.mode, f"MODE{self.mode}")

    @property
    def landed(self) -> bool | None:
        """True on the ground, False in the air, None unknown (EXTENDED_SYS_STATE)."""
        if self.landed_state == M.MAV_LANDED_STATE_ON_GROUND:
            return True
        if self.landed_state in (M.MAV_LANDED_STATE_IN_AIR, M.MAV_LANDED_STATE_TAKEOFF,
                                 M.MAV_LANDED_STATE_LANDING):
            return False
        return None

    @property
    def yaw(self) -> float:
        return self.attitude[2] if self.attitude is not None else 0.0

    def vehicle_state(self) -> VehicleState | None:
        """What the command queue's tick wants (None until a position has arrived)."""
        if self.position is None:
            return None
        return VehicleState(self.position, self.velocity, self.yaw, self.landed)

    def to_dict(self) -> dict[str, Any]:
        return {
            "system_id": self.system_id, "time_boot_ms": self.time_boot_ms, "mode": self.mode_name,
            "armed": self.armed,
            "landed_state": LANDED_STATE_NAMES.get(self.landed_state, str(self.landed_state)),
            "position": list(self.position) if self.position else None, "velocity": list(self.velocity),
            "attitude": list(self.attitude) if self.attitude else None,
            "battery_voltage": self.battery_voltage, "battery_remaining": self.battery_remaining,
            "battery_current": self.battery_current, "battery_consumed_mah": self.battery_consumed_mah,
            "home": list(self.home) if self.home else None,
            "gps_fix_type": self.gps_fix_type, "gps_satellites": self.gps_satellites,
            "global_position": list(self.global_position) if self.global_position else None,
            "heartbeats": self.heartbeats, "messages": self.messages, "texts": list(self.texts[-5:]),
            "range_down_m": self.range_down.distance_m if self.range_down is not None else None,
        }


class VehicleMirror:
    """Folds autopilot messages into a :class:`MirrorState`; ``update`` is called by one thread only."""

    def __init__(self, max_texts: int = 50) -> None:
        self._lock = threading.Lock()
        self._state = MirrorState()
        self._texts: deque[str] = deque(maxlen=max_texts)

    def snapshot(self) -> MirrorState:
        with self._lock:
            return self._state

    def update(self, msg: Any, wall: float) -> bool:
        """Fold one message from the autopilot; True if it was one the mirror uses."""
        t = msg.get_type()
        s = self._state
        changes: dict[str, Any] | None = None
        if t == "HEARTBEAT":
            armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
            changes = {"mode": msg.custom_mode, "base_mode": msg.base_mode,
                       "system_status": msg.system_status, "armed": armed, "heartbeats": s.heartbeats + 1,
                       "last_heartbeat_wall": wall,
                       "system_id": msg.get_srcSystem(), "component_id": msg.get_srcComponent()}
        elif t == "LOCAL_POSITION_NED":
            changes = {"position": (msg.x, msg.y, msg.z), "velocity": (msg.vx, msg.vy, msg.vz),
                       "time_boot_ms": msg.time_boot_ms, "position_time_ms": msg.time_boot_ms}
        elif t == "ATTITUDE":
            changes = {"attitude": (msg.roll, msg.pitch, msg.yaw), "time_boot_ms": msg.time_boot_ms}
        elif t == "EXTENDED_SYS_STATE":
            changes = {"landed_state": msg.landed_state}
        elif t == "SYS_STATUS":
            volt = msg.voltage_battery / 1000.0 if msg.voltage_battery != 65535 else None
            changes = {"battery_voltage": volt, "battery_remaining": msg.battery_remaining,
                       "sensors_present": msg.onboard_control_sensors_present,
                       "sensors_health": msg.onboard_control_sensors_health}
            if msg.current_battery >= 0:
                changes["battery_current"] = msg.current_battery / 100.0
        elif t == "BATTERY_STATUS" and msg.id == 0:
            used = float(msg.current_consumed) if msg.current_consumed >= 0 else None
            changes = {"battery_consumed_mah": used}
            if msg.current_battery >= 0:
                changes["battery_current"] = msg.current_battery / 100.0
        elif t == "HOME_POSITION":
            changes = {"home": (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)}
        elif t == "GPS_RAW_INT":
            changes = {"gps_fix_type": msg.fix_type, "gps_satellites": msg.satellites_visible}
        elif t == "GLOBAL_POSITION_INT":
            changes = {"global_position": (msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3,
                                           msg.relative_alt * 1e-3),
                       "time_boot_ms": msg.time_boot_ms}
            if s.attitude is None:  # heading until ATTITUDE arrives
                changes["attitude"] = (0.0, 0.0, math.radians(msg.hdg / 100.0) if msg.hdg != 65535 else 0.0)
        elif t == "POSITION_TARGET_LOCAL_NED":
            changes = {"position_target": PositionTargetEcho(msg.time_boot_ms, msg.type_mask,
                                                             (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz))}
        elif t == "RC_CHANNELS":
            n = max(0, min(int(msg.chancount), 18))
            chans = tuple(int(getattr(msg, f"chan{i}_raw")) for i in range(1, n + 1))
            changes = {"rc": RcReport(msg.time_boot_ms, chans, int(msg.rssi)),
                       "time_boot_ms": msg.time_boot_ms}
        elif t == "DISTANCE_SENSOR" and msg.orientation == M.MAV_SENSOR_ROTATION_PITCH_270:
            alt = -s.position[2] if s.position is not None else None
            roll, pitch = (s.attitude[0], s.attitude[1]) if s.attitude is not None else (0.0, 0.0)
            changes = {"range_down": RangeReport(msg.time_boot_ms, msg.current_distance / 100.0,
                                                 msg.min_distance / 100.0, msg.max_distance / 100.0, alt,
                                                 math.cos(roll) * math.cos(pitch)),
                       "time_boot_ms": msg.time_boot_ms}
        elif t == "STATUSTEXT":
            self._texts.append(msg.text)
            changes = {"texts": tuple(self._texts)}
        if changes is None:
            return False
        changes["messages"] = s.messages + 1
        with self._lock:
            self._state = _replaced(s, changes)
        return True


def _replaced(s: MirrorState, changes: dict[str, Any]) -> MirrorState:
    """``dataclasses.replace(s, **changes)`` for the mirror's one hot path (~90 messages a second per
    vehicle): :class:`MirrorState` has no ``__post_init__`` and no slots, so a copy of the instance's
    ``__dict__`` with the changes is the same new state, at a fifth of ``replace``'s cost (which walks the
    fields and calls ``__init__``). Every key is a field (the literal names in
    :meth:`VehicleMirror.update`)."""
    new = object.__new__(MirrorState)
    d = new.__dict__
    d.update(s.__dict__)
    d.update(changes)
    return new
