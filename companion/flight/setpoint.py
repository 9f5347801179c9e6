"""What the queue gives the MAVLink link each tick, and what the link tells it about the vehicle.

:class:`Setpoint` is one reference P_d (seed 000 Fig. 9) ready to be sent as
SET_POSITION_TARGET_LOCAL_NED; :class:`VehicleState` is the measured state the link mirrors from the
autopilot. Positions are local NED metres, angles radians (MAVLink's units).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

Vec3 = tuple[float, float, float]


class SetpointKind(Enum):
    """Which parts of the setpoint the link should send.

    POSITION: position + velocity + acceleration feed-forward + yaw (and yaw rate).
    VELOCITY: velocity only (+ yaw rate), for commands whose horizontal and vertical channels are
    both velocity streams (ExtVel / RCVel). The reference's position then follows the measured one
    (the autopilot is given none), so the next position command starts where the vehicle is.
    """

    POSITION = "POSITION"
    VELOCITY = "VELOCITY"


@dataclass(frozen=True)
class Setpoint:
    """One streamed reference.

    ``take_off``: the running command is a take-off (the link arms and sends MAV_CMD_NAV_TAKEOFF to
    ``takeoff_altitude``, metres up relative to the origin). ``allow_landing``: the running command
    may touch down. ``land_now``: that landing command's reference has reached its altitude or the
    vehicle reports it is on the ground; the link sends LAND. ``command_index`` is the queue index
    of the producing command and ``command_id`` its id (None while holding or inside a pause
    routine, then ``routine_id`` names the routine).
    """

    t_s: float
    p: Vec3
    v: Vec3
    a: Vec3
    yaw: float
    yaw_rate: float
    kind: SetpointKind = SetpointKind.POSITION
    take_off: bool = False
    takeoff_altitude: float | None = None
    allow_landing: bool = False
    land_now: bool = False
    command_index: int | None = None
    routine_id: str | None = None
    command_id: int | None = None

    def to_dict(self) -> dict[str, object]:
        return {"t_s": self.t_s, "p": list(self.p), "v": list(self.v), "a": list(self.a), "yaw": self.yaw,
                "yaw_rate": self.yaw_rate, "kind": self.kind.name, "take_off": self.take_off,
                "takeoff_altitude": self.takeoff_altitude, "allow_landing": self.allow_landing,
                "land_now": self.land_now, "command_index": self.command_index,
                "routine_id": self.routine_id, "command_id": self.command_id}


@dataclass(frozen=True)
class VehicleState:
    """The vehicle's measured state as mirrored by the link (local NED, yaw in radians).

    ``landed``: True when the autopilot reports it is on the ground (EXTENDED_SYS_STATE
    landed_state ON_GROUND), False when in the air, None when unknown.

    ``ground_alt``: the altitude (m up, local frame) of the ground under the vehicle from the downward
    range finder (the altitude when the reading came minus the distance read, made vertical with the
    tilt), ``ground_age_s`` how old that reading is (autopilot seconds); both None without an in-range
    reading (V_GROUND, :mod:`companion.flight.execution`).
    """

    p: Vec3
    v: Vec3 = (0.0, 0.0, 0.0)
    yaw: float = 0.0
    landed: bool | None = None
    ground_alt: float | None = None
    ground_age_s: float | None = None
