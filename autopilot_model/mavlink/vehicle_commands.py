"""The vehicle commands of the ArduCopter dialect, on the Navigator and the flight modes.

Each handler returns ``(MAV_RESULT, reason)``; a refusal carries the reason, which the dispatcher
sends as STATUSTEXT before the DENIED ACK (as ArduPilot's "PreArm: ..." messages). Commands:

COMPONENT_ARM_DISARM (param1 1/0; param2 21196 forces: skips pre-arm checks / disarms in flight),
NAV_TAKEOFF (param7 altitude above home; GUIDED or LOITER, armed, on the ground), NAV_LAND,
NAV_RETURN_TO_LAUNCH, DO_SET_MODE (and the SET_MODE message, acknowledged with command id 11 as
ArduPilot does), DO_REPOSITION (GUIDED; param2 bit 0 lets it switch to GUIDED), DO_CHANGE_SPEED,
MISSION_START (AUTO; accepted while disarmed), DO_PAUSE_CONTINUE, GET_HOME_POSITION, DO_SET_HOME,
CONDITION_YAW and DO_SET_ROI_LOCATION / DO_SET_ROI / DO_SET_ROI_NONE (:mod:`..modules.auto_yaw`),
PREFLIGHT_REBOOT_SHUTDOWN. The results follow ArduCopter's handlers (GCS_MAVLink_Copter.cpp,
GCS_Common.cpp); ``docs/conformance.md`` lists what the differential tests compare.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from autopilot_model.modules import flight_modes as fm
from autopilot_model.modules.navigation import LANDED_ON_GROUND
from taskflight_common.geo import geodetic_to_ned

from .commands import ACCEPTED, DENIED, FAILED, UNSUPPORTED, Command, CommandResult

if TYPE_CHECKING:
    from .commands import CommandDispatcher
    from .endpoint import MavlinkEndpoint
    from .streams import StreamScheduler
    from .transport import Peer

log = logging.getLogger(__name__)

FORCE_MAGIC = 21196
M = mavlink2


def _result(ok_why: tuple[bool, str]) -> CommandResult:
    """ArduCopter answers a refused arm, disarm, take-off or mode change with MAV_RESULT_FAILED."""
    ok, why = ok_why
    return (ACCEPTED, None) if ok else (FAILED, why)


class VehicleCommands:
    """Registers the vehicle's MAV_CMD handlers (and SET_MODE) on an endpoint."""

    def __init__(self, endpoint: MavlinkEndpoint, streams: StreamScheduler, commands: CommandDispatcher,
                 modes: fm.FlightModes) -> None:
        self.ep = endpoint
        self.streams = streams
        self.commands = commands
        self.modes = modes
        self.v = modes.v
        add = commands.add
        add(M.MAV_CMD_COMPONENT_ARM_DISARM, self.arm_disarm)
        add(M.MAV_CMD_NAV_TAKEOFF, self.takeoff)
        add(M.MAV_CMD_NAV_LAND, lambda c, p: self._mode(fm.LAND, "GCS land"))
        add(M.MAV_CMD_NAV_RETURN_TO_LAUNCH, lambda c, p: self._mode(fm.RTL, "GCS RTL"))
        add(M.MAV_CMD_DO_SET_MODE, self.do_set_mode)
        add(M.MAV_CMD_DO_REPOSITION, self.reposition)
        add(M.MAV_CMD_DO_CHANGE_SPEED, self.change_speed)
        add(M.MAV_CMD_MISSION_START, self.mission_start)
        add(M.MAV_CMD_DO_PAUSE_CONTINUE, self.pause_continue)
        add(M.MAV_CMD_GET_HOME_POSITION, self.get_home, dedup=False)
        add(M.MAV_CMD_DO_SET_HOME, self.set_home)
        add(M.MAV_CMD_CONDITION_YAW, self.condition_yaw)
        add(M.MAV_CMD_DO_SET_ROI_LOCATION, self.set_roi)
        add(M.MAV_CMD_DO_SET_ROI, self.set_roi)
        add(M.MAV_CMD_DO_SET_ROI_NONE, self.set_roi_none)
        add(M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, self.reboot)
        endpoint.add_handler("SET_MODE", self._on_set_mode)

    # --- arming --------------------------------------------------------------------------------
    def arm_disarm(self, cmd: Command, peer: Peer) -> CommandResult:
        p1 = cmd.finite(1, "arm/disarm flag")
        force = cmd.p(2) == FORCE_MAGIC
        nav = self.v.nav
        if p1 == 1:
            if nav.armed:
                return ACCEPTED, None
            if not force and not self.modes.allows_arming():
                return FAILED, f"Arm: Mode {self.modes.name} not armable"
            pilot = self.modes.pilot
            why = None if force or pilot is None else pilot.arm_refusal(self.modes.mode)
            if why:
                return FAILED, why
            return _result(nav.arm(force=force))
        if p1 == 0:
            return _result(nav.disarm(force=force))
        return DENIED, f"Arm: bad param1 {p1:g}"

    # --- take-off ------------------------------------------------------------------------------
    def takeoff(self, cmd: Command, peer: Peer) -> CommandResult:
        alt = cmd.finite(7, "takeoff altitude")
        nav = self.v.nav
        if self.modes.mode not in fm.TAKEOFF_MODES:
            return FAILED, f"Takeoff: not supported in {self.modes.name}"
        if not nav.armed:
            return FAILED, "Takeoff: not armed"
        if nav.landed_state != LANDED_ON_GROUND:
            return FAILED, "Takeoff: already flying"
        return _result(nav.takeoff(alt))

    # --- modes ---------------------------------------------------------------------------------
    def _mode(self, mode: int, reason: str) -> CommandResult:
        return _result(self.modes.set_mode(mode, reason))

    def do_set_mode(self, cmd: Command, peer: Peer) -> CommandResult:
        base = cmd.finite(1, "base mode")
        custom = cmd.finite(2, "custom mode")
        if not int(base) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return DENIED, "Mode: only custom modes are supported"
        if custom != int(custom) or custom not in fm.MODE_NAMES:
            return FAILED, f"No such mode {custom:g}"
        return self._mode(int(custom), "GCS command")

    def _on_set_mode(self, msg: Any, peer: Peer) -> None:
        if msg.target_system != self.ep.sysid:
            self.ep.stats["wrong_target"] += 1
            return
        reason: str | None
        if not msg.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            result, reason = DENIED, "Mode: only custom modes are supported"
        elif msg.custom_mode not in fm.MODE_NAMES:
            result, reason = FAILED, f"No such mode {msg.custom_mode}"
        else:
            result, reason = self._mode(msg.custom_mode, "GCS set_mode")
        if reason and result != ACCEPTED:
            self.ep.statustext(M.MAV_SEVERITY_WARNING, reason)
        self.ep.send(self.ep.mav.command_ack_encode(M.MAVLINK_MSG_ID_SET_MODE, result, 0, 0,
                                                    msg.get_srcSystem(), msg.get_srcComponent()), peer)

    # --- guided navigation ---------------------------------------------------------------------
    def reposition(self, cmd: Command, peer: Peer) -> CommandResult:
        flags = cmd.p(2)
        lat, lon, alt = cmd.p(5), cmd.p(6), cmd.p(7)
        may_switch = math.isfinite(flags) and int(flags) & M.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
        if self.modes.mode != fm.GUIDED and not may_switch:
            return DENIED, "Reposition: not in GUIDED"
        if not self.modes.in_air():
            return DENIED, "Reposition: not flying"
        cur = self.v.state.position_geodetic
        no_ll = cmd.is_int and cmd.x_int == 0 and cmd.y_int == 0
        if not math.isfinite(lat) or not math.isfinite(lon) or no_ll:
            lat, lon = cur[0], cur[1]
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            return DENIED, "Reposition: bad latitude/longitude"
        frame = cmd.frame if cmd.frame is not None else M.MAV_FRAME_GLOBAL
        if not math.isfinite(alt):
            alt_amsl = cur[2]
        elif frame in (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT):
            alt_amsl = alt
        elif frame in (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                       M.MAV_FRAME_GLOBAL_TERRAIN_ALT, M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT):
            alt_amsl = alt + self.v.home[2]
        else:
            return DENIED, f"Reposition: unsupported frame {frame}"
        if self.modes.mode != fm.GUIDED:
            ok, why = self.modes.set_mode(fm.GUIDED, "reposition")
            if not ok:
                return DENIED, why
        # ArduCopter ignores param1 (speed) and flies the new destination at WPNAV_SPEED: the GUIDED
        # sub-mode starts afresh (``pva_control_start``), dropping an earlier DO_CHANGE_SPEED
        self.modes.speed_override_h = None
        target = fm.GuidedTarget(pos=geodetic_to_ned(self.v.state.origin, lat, lon, alt_amsl))
        yaw = cmd.p(4)
        if math.isfinite(yaw):
            target.yaw = math.radians(yaw)
        else:  # ArduCopter's default auto yaw in GUIDED (WP_YAW_BEHAVIOR 2): face the destination
            n, e, _ = self.v.state.position_ned
            dn, de = target.pos[0] - n, target.pos[1] - e  # type: ignore[index]
            if math.hypot(dn, de) > 2.0:
                target.yaw = math.atan2(de, dn)
        return _result(self.modes.guided.set(target))

    def change_speed(self, cmd: Command, peer: Peer) -> CommandResult:
        """``handle_MAV_CMD_DO_CHANGE_SPEED``: param2 <= 0 DENIED; ground/air speed (0, 1) in AUTO, GUIDED
        and RTL (others: FAILED); climb / descent speed (2, 3) accepted there, flown at the envelope's."""
        kind = cmd.finite(1, "speed type")
        speed = cmd.finite(2, "speed")
        if not speed > 0:
            return DENIED, None
        if int(kind) not in (0, 1, 2, 3):
            return DENIED, None
        if self.modes.mode not in fm.SPEED_MODES:
            return FAILED, None
        if int(kind) in (0, 1):
            speed = min(speed, 50.0)
            self.modes.speed_override_h = speed
            if self.modes.mode == fm.GUIDED and self.modes.guided.target.pos is not None:
                self.modes.guided.set(self.modes.guided.target)
            runner = self.modes.mission_runner
            if self.modes.mode == fm.AUTO and runner is not None:
                runner.speed = speed
                runner.change_speed_now()
            elif self.modes.mode == fm.RTL and self.modes.in_air():
                self.modes.rtl_speed_changed()
        return ACCEPTED, None

    # --- heading -------------------------------------------------------------------------------
    def condition_yaw(self, cmd: Command, peer: Peer) -> CommandResult:
        """``handle_MAV_CMD_CONDITION_YAW``: 0 <= param1 <= 360 and param4 0 or 1, else FAILED; accepted
        in every mode (flown by the auto-yaw modes)."""
        angle, rate, direction, relative = (cmd.p(i) for i in (1, 2, 3, 4))
        if not (0.0 <= angle <= 360.0) or relative not in (0.0, 1.0):
            return FAILED, None
        rate = rate if math.isfinite(rate) else 0.0
        direction = direction if math.isfinite(direction) else 0.0
        self.modes.auto_yaw.set_fixed(angle, rate, direction, relative > 0,
                                      fly=self.modes.mode in fm.AUTO_YAW_MODES and self.modes.in_air())
        return ACCEPTED, None

    def set_roi(self, cmd: Command, peer: Peer) -> CommandResult:
        """DO_SET_ROI_LOCATION / DO_SET_ROI (params 5-7 the location; 0, 0 clears it)."""
        lat, lon, alt = cmd.p(5), cmd.p(6), cmd.p(7)
        if not (math.isfinite(lat) and math.isfinite(lon)) or not (-90 <= lat <= 90 and -180 <= lon <= 180):
            return DENIED, None
        alt = alt if math.isfinite(alt) else 0.0
        frame = cmd.frame if cmd.frame is not None else M.MAV_FRAME_GLOBAL_RELATIVE_ALT
        if frame in (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT):
            alt_amsl = alt
        else:
            alt_amsl = alt + self.v.home[2]
        self.modes.auto_yaw.set_roi(lat, lon, alt_amsl)
        return ACCEPTED, None

    def set_roi_none(self, cmd: Command, peer: Peer) -> CommandResult:
        self.modes.auto_yaw.reset()
        return ACCEPTED, None

    # --- reboot --------------------------------------------------------------------------------
    def reboot(self, cmd: Command, peer: Peer) -> CommandResult:
        """``handle_preflight_reboot``: FAILED while armed; param1 other than 1 (reboot) or 3 (reboot to the
        bootloader) UNSUPPORTED; otherwise ACCEPTED and the vehicle restarts (see :meth:`soft_reboot`)."""
        if self.v.nav.armed:
            return FAILED, None
        if cmd.p(1) not in (1.0, 3.0):
            return UNSUPPORTED, None
        self.commands.after_ack(self.soft_reboot)
        return ACCEPTED, None

    def soft_reboot(self) -> None:
        """What a ground station sees of a reboot, in the running process: the boot mode (STABILIZE), no
        mission in progress, the estimator and setpoints restarted, "Rebooting" then the banner text.
        Parameters and stored plans are kept (they persist anyway)."""
        self.ep.statustext(M.MAV_SEVERITY_INFO, "Rebooting")
        self.modes.set_mode(fm.STABILIZE, "reboot")
        runner = self.modes.mission_runner
        if runner is not None:
            runner.stop()
        self.v.guidance_reset_here()
        self.ep.statustext(M.MAV_SEVERITY_INFO, "ArduCopter model: restarted")

    # --- missions ------------------------------------------------------------------------------
    def mission_start(self, cmd: Command, peer: Peer) -> CommandResult:
        """As ArduCopter: switch to AUTO and start (or resume) the mission. Disarmed, it is accepted and
        the vehicle waits in AUTO (arming in AUTO is then refused unless forced, as ArduCopter with the
        default AUTO_OPTIONS). param1 (MAVLink: first item) > 0 starts at that item."""
        first = cmd.p(1)
        first_item = int(first) if math.isfinite(first) and first >= 1 else 0
        result = self._mode(fm.AUTO, "mission start")
        runner = self.modes.mission_runner
        if result[0] == ACCEPTED and runner is not None:
            ok, why = runner.mission_start(first_item)
            if not ok:
                return DENIED, why
        return result

    def pause_continue(self, cmd: Command, peer: Peer) -> CommandResult:
        p1 = cmd.finite(1, "pause/continue flag")
        if p1 == 0:
            return _result(self.modes.pause())
        if p1 == 1:
            return _result(self.modes.resume())
        return DENIED, f"Pause/continue: bad param1 {p1:g}"

    # --- home ----------------------------------------------------------------------------------
    def get_home(self, cmd: Command, peer: Peer) -> CommandResult:
        self.commands.after_ack(lambda: self.streams.send_now("HOME_POSITION", peer))
        return ACCEPTED, None

    def set_home(self, cmd: Command, peer: Peer) -> CommandResult:
        if cmd.p(1) not in (0.0, 1.0):
            return FAILED, None
        here = cmd.p(1) == 1 or (cmd.is_int and cmd.x_int == 0 and cmd.y_int == 0) or (
            not cmd.is_int and cmd.p(5) == 0 and cmd.p(6) == 0)
        if here:
            lat, lon, alt = self.v.state.position_geodetic
            self.modes.smart_rtl.set_home()  # Copter::set_home_to_current_location restarts SmartRTL's path
        else:
            lat, lon, alt = cmd.finite(5, "latitude"), cmd.finite(6, "longitude"), cmd.finite(7, "altitude")
            if cmd.frame in (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
                alt += self.v.home[2]
            if not (-90 <= lat <= 90 and -180 <= lon <= 180):
                return DENIED, "Set home: bad latitude/longitude"
            if (lat, lon) == (0.0, 0.0):
                return DENIED, "Set home: zero location"
            n, e, _ = geodetic_to_ned(self.v.state.origin, lat, lon, alt)
            if math.hypot(n, e) > 50_000:
                return DENIED, "Set home: more than 50 km from origin"
        self.v.home = (float(lat), float(lon), float(alt))
        self.v.nav.home_locked = True  # GCS_MAVLINK::handle_command_do_set_home: set_home(loc, lock=true)
        self.ep.statustext(M.MAV_SEVERITY_INFO, "Home position set")
        self.commands.after_ack(lambda: self.streams.send_now("HOME_POSITION", None))
        return ACCEPTED, None
