"""GUIDED targets as ArduCopter reads them: SET_POSITION_TARGET_LOCAL_NED and _GLOBAL_INT.

This mirrors ``GCS_MAVLINK_Copter::handle_message`` for the two messages:

* only acted on in GUIDED (otherwise ignored, counted ``target_not_guided``);
* ``force_set`` with acceleration not ignored: ignored (force is not supported);
* each ``*_ignore`` flag is true if *any* of its bits is set (ArduCopter tests ``type_mask & mask``);
* local frames (``handle_message_set_position_target_local_ned``): LOCAL_NED (x, y and z in metres
  from the EKF origin, the state interface's ``origin``, whatever home is: ArduCopter uses the packet's
  x, y, -z directly as its NEU target from the origin), LOCAL_OFFSET_NED (offset from the current
  position), BODY_NED and BODY_OFFSET_NED (offset from the current position, rotated by the heading;
  velocity and acceleration rotated too; yaw relative to the heading); any other frame: stop and hold;
* global frames: GLOBAL / GLOBAL_INT (altitude AMSL), GLOBAL_RELATIVE_ALT(_INT) (above home),
  GLOBAL_TERRAIN_ALT(_INT) (above the terrain, which is flat at home altitude here); a bad latitude or
  longitude or unknown frame: stop and hold;
* the combination decides the GUIDED sub-mode: position + velocity (+ acceleration) -> a moving
  position target with feed-forward (advanced between messages, see ``GuidedTargets``); velocity
  (+ acceleration) -> velocity; acceleration alone -> acceleration; position alone -> position;
  anything else (e.g. position with acceleration only) -> stop and hold;
* yaw (absolute, or relative in body frames) or yaw rate, else the current yaw is kept.

A non-finite number in a field that is not ignored makes the message invalid: nothing happens and it
is counted (``invalid_field``). What happens next (timeouts) is :class:`~autopilot_model.modules.
flight_modes.GuidedTargets`' job.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from autopilot_model.modules.flight_modes import GUIDED, FlightModes, GuidedTarget
from taskflight_common.geo import geodetic_to_ned

from .endpoint import InvalidFieldError, require_finite

if TYPE_CHECKING:
    from .endpoint import MavlinkEndpoint
    from .streams import StreamScheduler
    from .transport import Peer

log = logging.getLogger(__name__)

POS_IGNORE = 0b111
VEL_IGNORE = 0b111000
ACC_IGNORE = 0b111000000
FORCE_SET = 1 << 9
YAW_IGNORE = 1 << 10
YAW_RATE_IGNORE = 1 << 11

F = mavlink2
LOCAL_FRAMES = frozenset({F.MAV_FRAME_LOCAL_NED, F.MAV_FRAME_LOCAL_OFFSET_NED, F.MAV_FRAME_BODY_NED,
                          F.MAV_FRAME_BODY_OFFSET_NED})
BODY_FRAMES = frozenset({F.MAV_FRAME_BODY_NED, F.MAV_FRAME_BODY_OFFSET_NED})
OFFSET_FRAMES = frozenset({F.MAV_FRAME_LOCAL_OFFSET_NED, F.MAV_FRAME_BODY_NED, F.MAV_FRAME_BODY_OFFSET_NED})
ABSOLUTE_ALT_FRAMES = frozenset({F.MAV_FRAME_GLOBAL, F.MAV_FRAME_GLOBAL_INT})
HOME_ALT_FRAMES = frozenset({F.MAV_FRAME_GLOBAL_RELATIVE_ALT, F.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                             F.MAV_FRAME_GLOBAL_TERRAIN_ALT, F.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT})


def _rot(x: float, y: float, yaw: float) -> tuple[float, float]:
    c, s = math.cos(yaw), math.sin(yaw)
    return x * c - y * s, x * s + y * c


class GuidedTargetsProtocol:
    """Installs the two SET_POSITION_TARGET handlers and the POSITION_TARGET_LOCAL_NED builder."""

    def __init__(self, endpoint: MavlinkEndpoint, streams: StreamScheduler, modes: FlightModes) -> None:
        self.endpoint = endpoint
        self.modes = modes
        self.v = modes.v
        endpoint.add_handler("SET_POSITION_TARGET_LOCAL_NED", self._on_local)
        endpoint.add_handler("SET_POSITION_TARGET_GLOBAL_INT", self._on_global)
        streams.add_builder("POSITION_TARGET_LOCAL_NED", self.position_target_message)

    # --- helpers -------------------------------------------------------------------------------
    def _flags(self, msg: Any) -> tuple[bool, bool, bool, bool, bool] | None:
        m = msg.type_mask
        pos_i, vel_i, acc_i = bool(m & POS_IGNORE), bool(m & VEL_IGNORE), bool(m & ACC_IGNORE)
        yaw_i, rate_i = bool(m & YAW_IGNORE), bool(m & YAW_RATE_IGNORE)
        if m & FORCE_SET and not acc_i:
            return None
        if not pos_i:
            require_finite(msg.x if hasattr(msg, "x") else 0.0, msg.y if hasattr(msg, "y") else 0.0,
                           msg.z if hasattr(msg, "z") else msg.alt, what="position")
        if not vel_i:
            require_finite(msg.vx, msg.vy, msg.vz, what="velocity")
        if not acc_i:
            require_finite(msg.afx, msg.afy, msg.afz, what="acceleration")
        if not yaw_i:
            require_finite(msg.yaw, what="yaw")
        if not rate_i:
            require_finite(msg.yaw_rate, what="yaw rate")
        return pos_i, vel_i, acc_i, yaw_i, rate_i

    def _in_guided(self) -> bool:
        if self.modes.mode != GUIDED:
            self.endpoint.stats["target_not_guided"] += 1
            return False
        return True

    def _apply(self, pos: Any, vel: Any, acc: Any, yaw: float | None, rate: float | None,
               pos_i: bool, vel_i: bool, acc_i: bool) -> None:
        if not pos_i and not vel_i:
            t = GuidedTarget(pos=pos, vel=vel, acc=None if acc_i else acc, yaw=yaw, yaw_rate=rate)
        elif pos_i and not vel_i:
            t = GuidedTarget(vel=vel, acc=None if acc_i else acc, yaw=yaw, yaw_rate=rate)
        elif pos_i and vel_i and not acc_i:
            t = GuidedTarget(acc=acc, yaw=yaw, yaw_rate=rate)
        elif not pos_i and vel_i and acc_i:
            t = GuidedTarget(pos=pos, yaw=yaw, yaw_rate=rate)
        else:
            self.endpoint.stats["target_invalid_combination"] += 1
            self.modes.guided.stop()
            return
        ok, why = self.modes.guided.set(t)
        if not ok:
            self.endpoint.stats["target_refused"] += 1
            log.debug("guided target refused: %s", why)

    # --- handlers ------------------------------------------------------------------------------
    def _on_local(self, msg: Any, peer: Peer) -> None:
        if not self._in_guided():
            return
        frame = msg.coordinate_frame
        if frame not in LOCAL_FRAMES:
            self.endpoint.stats["target_bad_frame"] += 1
            self.modes.guided.stop()
            return
        flags = self._flags(msg)
        if flags is None:
            return
        pos_i, vel_i, acc_i, yaw_i, rate_i = flags
        heading = self.v.state.heading
        body = frame in BODY_FRAMES
        pos = vel = acc = None
        if not pos_i:
            x, y, z = msg.x, msg.y, msg.z
            if body:
                x, y = _rot(x, y, heading)
            if frame in OFFSET_FRAMES:
                n, e, d = self.v.state.position_ned
                pos = (n + x, e + y, d + z)
            else:  # LOCAL_NED: from the EKF origin (not home), as ArduCopter
                pos = (x, y, z)
        if not vel_i:
            vx, vy = _rot(msg.vx, msg.vy, heading) if body else (msg.vx, msg.vy)
            vel = (vx, vy, msg.vz)
        if not acc_i:
            ax, ay = _rot(msg.afx, msg.afy, heading) if body else (msg.afx, msg.afy)
            acc = (ax, ay, msg.afz)
        yaw = None if yaw_i else (msg.yaw + heading if body else msg.yaw)
        rate = None if rate_i else msg.yaw_rate
        self._apply(pos, vel, acc, yaw, rate, pos_i, vel_i, acc_i)

    def _on_global(self, msg: Any, peer: Peer) -> None:
        if not self._in_guided():
            return
        flags = self._flags(msg)
        if flags is None:
            return
        pos_i, vel_i, acc_i, yaw_i, rate_i = flags
        pos = None
        if not pos_i:
            if not (-900000000 <= msg.lat_int <= 900000000 and -1800000000 <= msg.lon_int <= 1800000000):
                self.endpoint.stats["target_bad_position"] += 1
                self.modes.guided.stop()
                return
            frame = msg.coordinate_frame
            if frame in ABSOLUTE_ALT_FRAMES:
                alt = msg.alt
            elif frame in HOME_ALT_FRAMES:
                alt = msg.alt + self.v.home[2]
            else:
                self.endpoint.stats["target_bad_frame"] += 1
                self.modes.guided.stop()
                return
            pos = geodetic_to_ned(self.v.state.origin, msg.lat_int * 1e-7, msg.lon_int * 1e-7, alt)
        vel = None if vel_i else (msg.vx, msg.vy, msg.vz)
        acc = None if acc_i else (msg.afx, msg.afy, msg.afz)
        yaw = None if yaw_i else msg.yaw
        rate = None if rate_i else msg.yaw_rate
        self._apply(pos, vel, acc, yaw, rate, pos_i, vel_i, acc_i)

    # --- telemetry -----------------------------------------------------------------------------
    def position_target_message(self) -> Any:
        """POSITION_TARGET_LOCAL_NED of the active GUIDED target (None outside GUIDED), in LOCAL_NED from
        the EKF origin (``GCS_MAVLINK_Copter::send_position_target_local_ned``)."""
        g = self.modes.guided
        if self.modes.mode != GUIDED or g.kind == "none":
            return None
        t = g.target
        mask = 0
        p, v, a = g.echo()  # PosVelAccel: the target as advanced with its feed-forward
        if g.timed_out:
            v = None if v is None else (0.0, 0.0, 0.0)
            a = None if a is None else (0.0, 0.0, 0.0)
        if p is None:
            mask |= POS_IGNORE
            p = (0.0, 0.0, 0.0)
        if v is None:
            mask |= VEL_IGNORE
            v = (0.0, 0.0, 0.0)
        if a is None:
            mask |= ACC_IGNORE
            a = (0.0, 0.0, 0.0)
        if t.yaw is None:
            mask |= YAW_IGNORE
        if t.yaw_rate is None:
            mask |= YAW_RATE_IGNORE
        return self.endpoint.mav.position_target_local_ned_encode(
            self.v.clock.time_boot_ms, F.MAV_FRAME_LOCAL_NED, mask, p[0], p[1], p[2], v[0], v[1], v[2],
            a[0], a[1], a[2], t.yaw or 0.0, t.yaw_rate or 0.0)


__all__ = ["GuidedTargetsProtocol", "InvalidFieldError"]
