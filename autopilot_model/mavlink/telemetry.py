"""Telemetry message builders: the vehicle's state as ArduCopter reports it.

Each builder reads the state interface (seed 002 Sec. 3.1: the estimator's view, not the truth), the
navigator, the flight modes and the battery monitor, and returns one pymavlink message. Every time
field is simulated time (``vehicle.clock``); SYSTEM_TIME's Unix time is the wall time the vehicle was
created at plus the simulated time elapsed, so a sped-up simulation stays self-consistent.

SYS_STATUS sets the present / enabled / healthy bits MAVSDK's health checks read: GPS (healthy with a
3D fix), AHRS (estimator ready), the pre-arm bit (no pre-arm failure), the control loops, the motor
outputs (enabled when armed) and the battery.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from autopilot_model.modules import flight_modes as fm
from taskflight_common.geo import ned_to_geodetic

if TYPE_CHECKING:
    from .endpoint import MavlinkEndpoint
    from .streams import StreamScheduler

M = mavlink2
S = M  # sensor bit names are long

#: ArduCopter's "guided enabled" base-mode modes
GUIDED_LIKE = frozenset({fm.AUTO, fm.RTL, fm.LOITER, fm.GUIDED, fm.BRAKE})

SENSORS_PRESENT = (S.MAV_SYS_STATUS_SENSOR_3D_GYRO | S.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                   | S.MAV_SYS_STATUS_SENSOR_3D_MAG | S.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
                   | S.MAV_SYS_STATUS_SENSOR_GPS | S.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
                   | S.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION | S.MAV_SYS_STATUS_SENSOR_YAW_POSITION
                   | S.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL | S.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
                   | S.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | S.MAV_SYS_STATUS_AHRS
                   | S.MAV_SYS_STATUS_SENSOR_BATTERY | S.MAV_SYS_STATUS_PREARM_CHECK)
ALWAYS_HEALTHY = (S.MAV_SYS_STATUS_SENSOR_3D_GYRO | S.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                  | S.MAV_SYS_STATUS_SENSOR_3D_MAG | S.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
                  | S.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
                  | S.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION | S.MAV_SYS_STATUS_SENSOR_YAW_POSITION
                  | S.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL | S.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
                  | S.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)

#: What the endpoint really supports (AUTOPILOT_VERSION.capabilities); mission bits are added by
#: the mission protocol's wiring when it is present.
BASE_CAPABILITIES = (M.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                     | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
                     | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                     | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT)
VERSION = (4, 7, 0)
"""ArduCopter's version whose parameter names the model uses: MAV_SYSID and MAV_GCS_SYSID (4.7; SYSID_THISMAV
and SYSID_MYGCS before), reported as a development build as ArduCopter 4.7.0-dev does."""


def _clamp_int(v: float, lo: int, hi: int) -> int:
    if not math.isfinite(v):
        return 0
    return int(max(lo, min(hi, round(v))))


class VehicleTelemetry:
    """Registers the state builders on the endpoint's stream scheduler."""

    def __init__(self, endpoint: MavlinkEndpoint, streams: StreamScheduler, modes: fm.FlightModes) -> None:
        self.ep = endpoint
        self.mav = endpoint.mav
        self.modes = modes
        self.v = modes.v
        self.capabilities = BASE_CAPABILITIES
        self.critical: Callable[[], bool] = lambda: False  # a failsafe is active (set by Safety wiring)
        #: (fence present, enabled, breached) as ArduPilot's AC_Fence::sys_status_*, set by the Safety wiring
        self.fence_state: Callable[[], tuple[bool, bool, bool]] = lambda: (False, False, False)
        self.unix0_us = int(time.time() * 1e6)  # wall time at the simulation's t = 0
        b = streams.add_builder
        b("HEARTBEAT", self.heartbeat)
        b("SYS_STATUS", self.sys_status)
        b("BATTERY_STATUS", self.battery_status)
        b("ATTITUDE", self.attitude)
        b("ATTITUDE_QUATERNION", self.attitude_quaternion)
        b("GLOBAL_POSITION_INT", self.global_position_int)
        b("LOCAL_POSITION_NED", self.local_position_ned)
        b("GPS_RAW_INT", self.gps_raw_int)
        b("VFR_HUD", self.vfr_hud)
        b("HOME_POSITION", self.home_position)
        b("EXTENDED_SYS_STATE", self.extended_sys_state)
        b("SYSTEM_TIME", self.system_time)
        b("AUTOPILOT_VERSION", self.autopilot_version)
        if not streams.supports("MISSION_CURRENT"):
            b("MISSION_CURRENT", lambda: self.mav.mission_current_encode(0, 0, 0, 0))
        modes.on_mode_change(self._announce_mode)
        self.v.nav.on_event(lambda text: endpoint.statustext(M.MAV_SEVERITY_INFO, text))

    def _announce_mode(self, old: int, new: int, reason: str) -> None:
        text = f"Mode {fm.mode_name(new)}" + (f" ({reason})" if reason else "")
        self.ep.statustext(M.MAV_SEVERITY_NOTICE if reason else M.MAV_SEVERITY_INFO, text)

    # --- heartbeat and status ------------------------------------------------------------------
    def base_mode(self) -> int:
        bm = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED \
            | M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if self.modes.mode in GUIDED_LIKE:
            bm |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        if self.v.nav.armed:
            bm |= M.MAV_MODE_FLAG_SAFETY_ARMED
        return bm

    def system_status(self) -> int:
        if self.critical():
            return M.MAV_STATE_CRITICAL
        if not self.v.estimator.healthy:
            return M.MAV_STATE_CALIBRATING
        return M.MAV_STATE_ACTIVE if self.modes.in_air() else M.MAV_STATE_STANDBY

    def heartbeat(self) -> Any:
        return self.mav.heartbeat_encode(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                         self.base_mode(),
                                         self.modes.mode, self.system_status(), 3)

    def _battery(self) -> tuple[float, float, float, float]:
        """(voltage V, current A, consumed mAh, remaining %)"""
        bat = self.v.battery
        volt = self.v.battery_voltage or bat.voltage
        return volt, bat.current_a, bat.consumed_mah, bat.remaining_pct

    def sys_status(self) -> Any:
        v = self.v
        health = ALWAYS_HEALTHY
        gps_ok = v.gps.fix_type >= 3
        if gps_ok:
            health |= S.MAV_SYS_STATUS_SENSOR_GPS
        if v.estimator.healthy:
            health |= S.MAV_SYS_STATUS_AHRS
        volt, amps, _, pct = self._battery()
        if pct > 10:
            health |= S.MAV_SYS_STATUS_SENSOR_BATTERY
        if not v.nav.prearm_failures() and self.modes.allows_arming():
            health |= S.MAV_SYS_STATUS_PREARM_CHECK
        present = SENSORS_PRESENT
        fence_present, fence_enabled, fence_breached = self.fence_state()
        if fence_present:
            present |= S.MAV_SYS_STATUS_GEOFENCE
        if not fence_breached:  # ArduPilot: healthy unless breached, whether or not enabled
            health |= S.MAV_SYS_STATUS_GEOFENCE
        enabled = present & ~S.MAV_SYS_STATUS_GEOFENCE
        if fence_enabled:
            enabled |= S.MAV_SYS_STATUS_GEOFENCE
        if not v.nav.armed:
            enabled &= ~S.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
        stats = self.ep.stats
        return self.mav.sys_status_encode(
            present, enabled, health, 0, _clamp_int(volt * 1000, 0, 65535),
            _clamp_int(amps * 100, -1, 32767), _clamp_int(pct, -1, 100), 0,
            min(65535, stats["bad_crc"] + stats["truncated"]), 0, 0, 0, 0)

    def battery_status(self) -> Any:
        volt, amps, used, pct = self._battery()
        cells = [65535] * 10
        cells[0] = _clamp_int(volt * 1000, 0, 65534)
        return self.mav.battery_status_encode(
            0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 32767, cells,
            _clamp_int(amps * 100, -1, 32767), _clamp_int(used, -1, 2**31 - 1), -1,
            _clamp_int(pct, -1, 100), 0, M.MAV_BATTERY_CHARGE_STATE_OK, [0, 0, 0, 0], 0, 0)

    # --- attitude and position -----------------------------------------------------------------
    def attitude(self) -> Any:
        r, p, y = self.v.state.euler
        w = self.v.state.body_rates
        return self.mav.attitude_encode(self.v.clock.time_boot_ms, r, p, y, w[0], w[1], w[2])

    def attitude_quaternion(self) -> Any:
        q = self.v.state.quat
        w = self.v.state.body_rates
        return self.mav.attitude_quaternion_encode(self.v.clock.time_boot_ms, q[0], q[1], q[2], q[3],
                                                   w[0], w[1], w[2], [0.0, 0.0, 0.0, 0.0])

    def _heading_cdeg(self) -> int:
        return round(math.degrees(self.v.state.euler[2]) * 100) % 36000

    def global_position_int(self) -> Any:
        st = self.v.state
        lat, lon, alt = st.position_geodetic
        vn, ve, vd = st.velocity_ned
        rel = alt - self.v.home[2]
        return self.mav.global_position_int_encode(
            self.v.clock.time_boot_ms, _clamp_int(lat * 1e7, -900000000, 900000000),
            _clamp_int(lon * 1e7, -1800000000, 1800000000), _clamp_int(alt * 1000, -2**31, 2**31 - 1),
            _clamp_int(rel * 1000, -2**31, 2**31 - 1), _clamp_int(vn * 100, -32768, 32767),
            _clamp_int(ve * 100, -32768, 32767), _clamp_int(vd * 100, -32768, 32767), self._heading_cdeg())

    def local_position_ned(self) -> Any:
        st = self.v.state
        n, e, d = st.position_ned
        vn, ve, vd = st.velocity_ned
        return self.mav.local_position_ned_encode(self.v.clock.time_boot_ms, n, e, d, vn, ve, vd)

    def gps_raw_int(self) -> Any:
        gps = self.v.gps
        sample = gps.sample
        if sample is None or gps.fix_type < 2:
            return self.mav.gps_raw_int_encode(self.v.clock.time_usec, gps.fix_type, 0, 0, 0, 65535, 65535,
                                               65535, 65535, gps.satellites)
        lat, lon, alt = ned_to_geodetic(self.v.state.origin, sample[0], sample[1], sample[2])
        vel = math.hypot(sample[3], sample[4])
        cog = round(math.degrees(math.atan2(sample[4], sample[3])) * 100) % 36000 if vel > 0.2 else 0
        eph, epv = gps.eph_m, gps.epv_m
        return self.mav.gps_raw_int_encode(
            self.v.clock.time_usec, gps.fix_type, _clamp_int(lat * 1e7, -900000000, 900000000),
            _clamp_int(lon * 1e7, -1800000000, 1800000000), _clamp_int(alt * 1000, -2**31, 2**31 - 1),
            _clamp_int(eph * 100, 0, 65534), _clamp_int(epv * 100, 0, 65534), _clamp_int(vel * 100, 0, 65534),
            cog, gps.satellites, _clamp_int(alt * 1000, -2**31, 2**31 - 1), _clamp_int(eph * 1000, 0, 2**31),
            _clamp_int(epv * 1000, 0, 2**31), 300, 0, 0)

    def vfr_hud(self) -> Any:
        st = self.v.state
        vn, ve, vd = st.velocity_ned
        gs = math.hypot(vn, ve)
        thr = 0
        if self.v.nav.armed:
            thr = _clamp_int(100 * self.v.control.out[0] / (4 * self.v.airframe.thrust_max), 0, 100)
        return self.mav.vfr_hud_encode(gs, gs, self._heading_cdeg() // 100, thr, st.position_geodetic[2], -vd)

    def home_position(self) -> Any:
        """As ArduCopter (GCS_MAVLINK::send_home_position): lat/lon/alt only; x, y, z zero and q NaN, so
        clients take local positions from LOCAL_POSITION_NED (home and the EKF origin may differ)."""
        lat, lon, alt = self.v.home
        nan = float("nan")
        return self.mav.home_position_encode(
            _clamp_int(lat * 1e7, -900000000, 900000000), _clamp_int(lon * 1e7, -1800000000, 1800000000),
            _clamp_int(alt * 1000, -2**31, 2**31 - 1), 0.0, 0.0, 0.0, [nan, nan, nan, nan], 0.0, 0.0, 0.0,
            self.v.clock.time_usec)

    def extended_sys_state(self) -> Any:
        return self.mav.extended_sys_state_encode(M.MAV_VTOL_STATE_UNDEFINED, self.v.nav.landed_state)

    def system_time(self) -> Any:
        return self.mav.system_time_encode(self.unix0_us + self.v.clock.time_usec, self.v.clock.time_boot_ms)

    def autopilot_version(self) -> Any:
        major, minor, patch = VERSION
        sw = (major << 24) | (minor << 16) | (patch << 8) | M.FIRMWARE_VERSION_TYPE_DEV
        return self.mav.autopilot_version_encode(
            self.capabilities, sw, 0, 0, 0, b"tfmodel\x00", b"\x00" * 8, b"\x00" * 8, 0, 0,
            self.ep.sysid, [0] * 18)
