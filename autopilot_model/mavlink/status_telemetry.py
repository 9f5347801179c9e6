"""Status messages a ground station reads from ArduCopter: the fence, the EKF, the navigation controller,
the EKF origin; and MAV_CMD_DO_FENCE_ENABLE.

* FENCE_STATUS (ArduPilot ``GCS_MAVLINK::send_fence_status``): only while a fence is enabled; breach
  status, count, type (MINALT, MAXALT, BOUNDARY; the last breached kind in that order wins, as
  ArduPilot), the time of the breach (ms since boot), mitigation NONE (ArduCopter's avoidance is not
  limiting). Sent at once on a new breach to every link, besides its stream (EXTENDED_STATUS).
* MAV_CMD_DO_FENCE_ENABLE (``handle_command_do_fence_enable``): param1 0 disable, 1 enable (FAILED when
  none of the types asked for is present), 2 disable the floor; param2 the FENCE_TYPE bits (0 = all).
* EKF_STATUS_REPORT (EXTRA3): ArduPilot's flags from the estimator's state (attitude and velocities once
  initialised, the positions once its position is trusted, "uninitialised" before); the variances are the
  normalised position innovation (the model's estimator has the position test only), compass 0.
* NAV_CONTROLLER_OUTPUT (EXTENDED_STATUS, ArduCopter's ``send_nav_controller_output``): the attitude (the
  model's cascade has no separate attitude target) and the yaw target; bearing and distance to the
  position target the setpoint generator is flying (GUIDED, RTL, AUTO), 0 without one; altitude error.
* GPS_GLOBAL_ORIGIN (no stream group, as ArduPilot): the EKF origin once the estimator has one.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from autopilot_model.modules import fence as fm

from .commands import ACCEPTED, FAILED, Command, CommandResult

if TYPE_CHECKING:
    from autopilot_model.modules.vehicle_api import VehicleApi

    from .commands import CommandDispatcher
    from .endpoint import MavlinkEndpoint
    from .streams import StreamScheduler
    from .transport import Peer

M = mavlink2
EKF_READY_FLAGS = (M.EKF_ATTITUDE | M.EKF_VELOCITY_HORIZ | M.EKF_VELOCITY_VERT | M.EKF_POS_HORIZ_REL
                   | M.EKF_POS_HORIZ_ABS | M.EKF_POS_VERT_ABS | M.EKF_PRED_POS_HORIZ_REL
                   | M.EKF_PRED_POS_HORIZ_ABS)
"""What ArduCopter's EKF3 reports in a GPS hover (0x33F)."""


def _i(v: float, lo: int, hi: int) -> int:
    return int(max(lo, min(hi, round(v)))) if math.isfinite(v) else 0


class FenceLink:
    """FENCE_STATUS and MAV_CMD_DO_FENCE_ENABLE for the vehicle's geofence (:class:`.fence.Fence`)."""

    def __init__(self, endpoint: MavlinkEndpoint, streams: StreamScheduler, commands: CommandDispatcher,
                 fence: fm.Fence) -> None:
        self.ep = endpoint
        self.fence = fence
        streams.add_builder("FENCE_STATUS", self.fence_status)
        commands.add(M.MAV_CMD_DO_FENCE_ENABLE, self.do_fence_enable)

    def fence_status(self) -> Any:
        f = self.fence
        if not f.enabled:
            return None
        breaches = f.breached
        kind = M.FENCE_BREACH_NONE
        if breaches & fm.ALT_MIN:
            kind = M.FENCE_BREACH_MINALT
        if breaches & fm.ALT_MAX:
            kind = M.FENCE_BREACH_MAXALT
        if breaches & (fm.CIRCLE | fm.POLYGON):
            kind = M.FENCE_BREACH_BOUNDARY
        return self.ep.mav.fence_status_encode(int(bool(breaches)), f.breach_count, kind,
                                               f.breach_time_ms & 0xFFFFFFFF, M.FENCE_MITIGATE_NONE)

    def send_now(self) -> None:
        """A new breach: FENCE_STATUS to every link at once (ArduPilot's ``GCS_SEND_MESSAGE``)."""
        msg = self.fence_status()
        if msg is not None:
            self.ep.send(msg, None)

    def do_fence_enable(self, cmd: Command, peer: Peer) -> CommandResult:
        action = cmd.p(1)
        types = cmd.p(2)
        fences = int(types) & 0xFF if math.isfinite(types) and int(types) else fm.ALL_FENCES
        if action == fm.DISABLE_FENCE:
            self.fence.enable(False, fences)
            return ACCEPTED, None
        if action == fm.ENABLE_FENCE:
            if not self.fence.present() & fences:
                return FAILED, "Fence: none of the fences asked for is configured"
            self.fence.enable(True, fences)
            return ACCEPTED, None
        if action == fm.DISABLE_ALT_MIN_FENCE:
            self.fence.enable(False, fm.ALT_MIN)
            return ACCEPTED, None
        return FAILED, None


class StatusTelemetry:
    """EKF_STATUS_REPORT, NAV_CONTROLLER_OUTPUT and GPS_GLOBAL_ORIGIN builders on the stream scheduler."""

    def __init__(self, endpoint: MavlinkEndpoint, streams: StreamScheduler, vehicle: VehicleApi) -> None:
        self.ep = endpoint
        self.v = vehicle
        b = streams.add_builder
        b("EKF_STATUS_REPORT", self.ekf_status_report)
        b("NAV_CONTROLLER_OUTPUT", self.nav_controller_output)
        b("GPS_GLOBAL_ORIGIN", self.gps_global_origin)

    def ekf_status_report(self) -> Any:
        est = self.v.estimator
        flags = 0
        if est.initialised:
            flags |= M.EKF_ATTITUDE | M.EKF_VELOCITY_HORIZ | M.EKF_VELOCITY_VERT
            if est.position_ok:
                flags = EKF_READY_FLAGS
            else:
                flags |= M.EKF_CONST_POS_MODE
        else:
            flags = M.EKF_UNINITIALIZED
        var = float(est.pos_variance)
        var = var if math.isfinite(var) else 99.0
        return self.ep.mav.ekf_status_report_encode(flags, var, var, var, 0.0, 0.0, 0.0)

    def _position_target(self) -> tuple[float, float, float] | None:
        g = self.v.guidance
        if not self.v.nav.armed:
            return None
        t = g.target
        return None if t is None else (float(t[0]), float(t[1]), float(t[2]))

    def nav_controller_output(self) -> Any:
        st = self.v.state
        roll, pitch, _ = st.euler
        yaw_target = math.degrees(self.v.guidance.yaw)
        bearing, dist, alt_err = 0, 0, 0.0
        target = self._position_target()
        if target is not None:
            n, e, d = st.position_ned
            dn, de = target[0] - n, target[1] - e
            dist = _i(math.hypot(dn, de), 0, 65535)
            bearing = _i(math.degrees(math.atan2(de, dn)), -180, 180) if dist > 0 else 0
            alt_err = float(d - target[2])
        return self.ep.mav.nav_controller_output_encode(
            math.degrees(roll), math.degrees(pitch), _i(yaw_target, -32768, 32767), bearing, dist,
            alt_err, 0.0, 0.0)

    def gps_global_origin(self) -> Any:
        if not self.v.estimator.initialised:
            return None
        lat, lon, alt = self.v.state.origin
        return self.ep.mav.gps_global_origin_encode(_i(lat * 1e7, -900000000, 900000000),
                                                    _i(lon * 1e7, -1800000000, 1800000000),
                                                    _i(alt * 1000, -2**31, 2**31 - 1), self.v.clock.time_usec)
