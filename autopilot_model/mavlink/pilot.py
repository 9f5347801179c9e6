"""The pilot's MAVLink: RC_CHANNELS_OVERRIDE and MANUAL_CONTROL in, RC_CHANNELS and SERVO_OUTPUT_RAW out.

* RC_CHANNELS_OVERRIDE and MANUAL_CONTROL are taken only from the ground station's system id
  (MAV_GCS_SYSID), as ArduCopter's ``handle_rc_channels_override`` / ``handle_manual_control`` do, and
  MANUAL_CONTROL only when its ``target`` is this vehicle. Both count as the ground station being there
  (``sysid_mygcs_seen``: the GCS failsafe's timer). The channels and the RC failsafe are
  :class:`~autopilot_model.modules.rc_input.RcInput`'s.
* RC_CHANNELS: the channel values the model flies (``radio_in``, PWM us), ``chancount`` the channels
  received so far (0 before any RC), ``rssi`` 255 (unknown, ArduCopter without RSSI_TYPE) and 0 while
  the RC failsafe is on.
* SERVO_OUTPUT_RAW: the four motor outputs in microseconds, 1000 + 1000 x the motor command (ArduCopter's
  MOT_PWM_MIN / MOT_PWM_MAX, motor order of the Quad X), 1000 when disarmed.

Both go out in ArduCopter's RC_CHANNELS stream group (REQUEST_DATA_STREAM) and on SET_MESSAGE_INTERVAL.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from autopilot_model.modules.rc_input import RcInput

    from .endpoint import MavlinkEndpoint
    from .streams import StreamScheduler
    from .transport import Peer

PWM_MIN = 1000
PWM_MAX = 2000


class PilotLink:
    """Installs the pilot-input handlers and the RC / servo builders on an endpoint."""

    def __init__(self, endpoint: MavlinkEndpoint, streams: StreamScheduler, rc: RcInput) -> None:
        self.ep = endpoint
        self.rc = rc
        self.v = rc.v
        endpoint.add_handler("RC_CHANNELS_OVERRIDE", self._on_override)
        endpoint.add_handler("MANUAL_CONTROL", self._on_manual_control)
        streams.add_builder("RC_CHANNELS", self.rc_channels)
        streams.add_builder("SERVO_OUTPUT_RAW", self.servo_output_raw)

    def _from_gcs(self, msg: Any) -> bool:
        if msg.get_srcSystem() != int(self.v.params.get("MAV_GCS_SYSID")):
            self.ep.stats["pilot_not_gcs"] += 1
            return False
        self.ep.last_gcs_heartbeat_s = self.ep.clock.now()
        return True

    def _on_override(self, msg: Any, peer: Peer) -> None:
        if not self._from_gcs(msg):
            return
        values = [msg.chan1_raw, msg.chan2_raw, msg.chan3_raw, msg.chan4_raw, msg.chan5_raw, msg.chan6_raw,
                  msg.chan7_raw, msg.chan8_raw]
        values += [getattr(msg, f"chan{i}_raw", 0) for i in range(9, 17)]
        self.rc.override(values)

    def _on_manual_control(self, msg: Any, peer: Peer) -> None:
        if not self._from_gcs(msg) or msg.target != self.ep.sysid:
            return
        self.rc.manual_control(msg.x, msg.y, msg.z, msg.r)

    def rc_channels(self) -> Any:
        rc = self.rc
        ch = [*list(rc.radio_in), 0, 0]
        rssi = 0 if rc.failsafe else 255
        return self.ep.mav.rc_channels_encode(self.v.clock.time_boot_ms, rc.chancount, *ch[:18], rssi)

    def servo_output_raw(self) -> Any:
        cmd = self.v.world.cmd
        armed = self.v.nav.armed
        out = [PWM_MIN + round((PWM_MAX - PWM_MIN) * min(max(float(c), 0.0), 1.0)) if armed else PWM_MIN
               for c in cmd[:4]]
        out += [0] * 12
        return self.ep.mav.servo_output_raw_encode(self.v.clock.time_usec & 0xFFFFFFFF, 0, *out)
