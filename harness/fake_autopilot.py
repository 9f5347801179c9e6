"""A scripted fake ArduCopter on a real UDP socket, for the companion's link tests (no tests here).

:class:`FakeAutopilot` is a stand-in used only where the real model cannot easily be made to
misbehave: commands refused or never ACKed, SET_MESSAGE_INTERVAL unsupported, RC sticks moved. It is
a collaborator, not the thing under test: it speaks real MAVLink 2 bytes (pymavlink, ardupilotmega)
on ``udpin:127.0.0.1:PORT`` and answers whoever sent to it, as ArduPilot's UDP server does. Its
"physics" are deliberately trivial (a 1 m/s takeoff climb, a 1 m/s LAND descent, jumps to position
setpoints). The conformance tests run against ArduCopter SITL and the bundled autopilot model.

Like ArduCopter it streams nothing but HEARTBEAT until asked (SET_MESSAGE_INTERVAL or
REQUEST_DATA_STREAM); stream rates and ``time_boot_ms`` run on its clock, wall time times ``speedup``.
"""

from __future__ import annotations

import math
import os
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from taskflight_common.ardupilot import CopterMode
from taskflight_common.ports import free_ports

M = mavlink2
#: ArduCopter custom modes (HEARTBEAT custom_mode)
STABILIZE, ALT_HOLD, AUTO, GUIDED, LOITER, RTL, LAND, BRAKE = (
    CopterMode.STABILIZE, CopterMode.ALT_HOLD, CopterMode.AUTO, CopterMode.GUIDED, CopterMode.LOITER,
    CopterMode.RTL, CopterMode.LAND, CopterMode.BRAKE)
#: MAV_CMD_COMPONENT_ARM_DISARM param2 that forces a disarm in flight
FORCE_DISARM = 21196
#: ArduCopter's REQUEST_DATA_STREAM groups, restricted to what the fake produces
STREAM_GROUPS: dict[int, tuple[str, ...]] = {
    M.MAV_DATA_STREAM_EXTENDED_STATUS: ("SYS_STATUS", "GPS_RAW_INT", "POSITION_TARGET_LOCAL_NED"),
    M.MAV_DATA_STREAM_RC_CHANNELS: ("RC_CHANNELS",),
    M.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),
    M.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
    M.MAV_DATA_STREAM_EXTRA3: ("SYSTEM_TIME", "EXTENDED_SYS_STATE", "HOME_POSITION", "BATTERY_STATUS"),
}
_POS_IGNORED = (M.POSITION_TARGET_TYPEMASK_X_IGNORE | M.POSITION_TARGET_TYPEMASK_Y_IGNORE
                | M.POSITION_TARGET_TYPEMASK_Z_IGNORE)
_SENSORS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_GPS
            | M.MAV_SYS_STATUS_PREARM_CHECK)

Policy = Callable[[Any], int | None]


def unanswered_url() -> str:
    """A companion's autopilot URL that nobody answers (a free loopback UDP port): for companions built
    and never flown."""
    return f"udpout:127.0.0.1:{free_ports(1, socket.SOCK_DGRAM)[0]}"


@dataclass(frozen=True)
class Received:
    """One message from the companion, with when it arrived (wall ``time.monotonic()`` and fake clock)."""

    msg: Any
    wall: float
    time_boot_ms: int


@dataclass(frozen=True)
class DataStreamRequest:
    stream_id: int
    rate_hz: int
    start: bool


class FakeAutopilot:
    """A scripted ArduCopter (see module docstring); use as a context manager.

    ``policy`` maps a MAV_CMD id to a function of the COMMAND_LONG returning the MAV_RESULT to ACK
    (None: send no ACK); commands without a policy are ACCEPTED. Accepted commands then have their
    default effect (modes, arming, takeoff, streams), which may still fail as ArduCopter would.
    """

    def __init__(self, *, port: int = 0, heartbeat_hz: float = 10.0, speedup: float = 1.0,
                 message_interval_supported: bool = True, mode: int = STABILIZE,
                 home: tuple[float, float, float] = (-35.363262, 149.165237, 584.0),
                 home_offset_m: float = 0.0, poll_s: float = 0.004) -> None:
        self._conn: Any = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=1,
                                                     source_component=1, dialect="ardupilotmega")
        self._conn.mav = M.MAVLink(self._conn, srcSystem=1, srcComponent=1)  # MAVLink 2 whatever the env
        self._conn.mav.robust_parsing = True
        self._conn.WIRE_PROTOCOL_VERSION = "2.0"
        self.port: int = self._conn.port.getsockname()[1]
        self.heartbeat_hz = heartbeat_hz
        self.speedup = speedup
        self.message_interval_supported = message_interval_supported
        self.policy: dict[int, Policy] = {}
        # the vehicle (tests may set these; the fake's thread reads them)
        self.mode = mode
        self.armed = False
        self.landed = True
        self.position: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.yaw = 0.0
        self.home = home
        self.home_offset_m = home_offset_m  # height of the local origin above home
        self.rc: list[int] = [1500] * 18
        self.target: Any = None  # the last SET_POSITION_TARGET_LOCAL_NED followed
        # what happened
        self.received: list[Received] = []
        self.data_stream_requests: list[DataStreamRequest] = []
        self.acks: list[tuple[int, int]] = []  # (command, result) sent
        self.sent: Counter[str] = Counter()
        self._intervals: dict[str, float] = {}  # message name -> interval, fake seconds
        self._due: dict[str, float] = {}
        self._outbox: list[str] = []
        self._climb_to: float | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._poll_s = poll_s
        self._wall0 = time.monotonic()
        self._builders: dict[str, Callable[[], Any]] = {
            "LOCAL_POSITION_NED": self._local_position, "ATTITUDE": self._attitude,
            "EXTENDED_SYS_STATE": self._extended_sys_state, "GLOBAL_POSITION_INT": self._global_position,
            "SYS_STATUS": self._sys_status, "HOME_POSITION": self._home_position,
            "RC_CHANNELS": self._rc_channels, "GPS_RAW_INT": self._gps_raw,
            "SYSTEM_TIME": self._system_time, "POSITION_TARGET_LOCAL_NED": self._position_target,
            "BATTERY_STATUS": self._battery_status,
            "DISTANCE_SENSOR": self._distance_sensor,
        }

    # --- lifecycle -----------------------------------------------------------------------------------
    def start(self) -> FakeAutopilot:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="fake-autopilot", daemon=True)
            self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._conn.close()

    def __enter__(self) -> FakeAutopilot:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def time_boot_ms(self) -> int:
        return int((time.monotonic() - self._wall0) * self.speedup * 1000.0) & 0xFFFFFFFF

    # --- scripting -----------------------------------------------------------------------------------
    def refuse(self, cmd_id: int, times: int = 1, result: int = M.MAV_RESULT_FAILED) -> None:
        """ACK the next ``times`` ``cmd_id`` with ``result``, then as before (default: accept)."""
        self._script(cmd_id, times, result)

    def ignore(self, cmd_id: int, times: int = 1) -> None:
        """Send no ACK for the next ``times`` ``cmd_id``, then as before."""
        self._script(cmd_id, times, None)

    def _script(self, cmd_id: int, times: int, result: int | None) -> None:
        before = self.policy.get(cmd_id)
        left = [times]

        def scripted(msg: Any) -> int | None:
            if left[0] > 0:
                left[0] -= 1
                return result
            return before(msg) if before is not None else M.MAV_RESULT_ACCEPTED

        self.policy[cmd_id] = scripted

    def set_mode(self, mode: int) -> None:
        """Change mode as a transmitter or another GCS would."""
        self.mode = mode

    def set_armed(self, armed: bool) -> None:
        """Arm or disarm as a transmitter or another GCS would."""
        self.armed = armed

    # --- what the companion sent -----------------------------------------------------------------------
    def messages(self, msg_type: str) -> list[Received]:
        with self._lock:
            return [r for r in self.received if r.msg.get_type() == msg_type]

    def commands(self, cmd_id: int) -> list[Any]:
        return [r.msg for r in self.messages("COMMAND_LONG") if r.msg.command == cmd_id]

    def count(self, msg_type: str) -> int:
        return len(self.messages(msg_type))

    def setpoints(self) -> list[Any]:
        return [r.msg for r in self.messages("SET_POSITION_TARGET_LOCAL_NED")]

    @property
    def stream_intervals(self) -> dict[str, float]:
        """Message name -> interval (s of the fake's clock) currently streamed."""
        with self._lock:
            return dict(self._intervals)

    # --- the thread ------------------------------------------------------------------------------------
    def _run(self) -> None:
        next_hb = time.monotonic()
        last_s = self.time_boot_ms / 1000.0
        while not self._stop.is_set():
            try:
                msg = self._conn.recv_match(blocking=True, timeout=self._poll_s)
                while msg is not None:
                    self._handle(msg)
                    msg = self._conn.recv_match(blocking=False)
            except (OSError, ValueError):
                if self._stop.wait(0.01):
                    return
                continue
            wall = time.monotonic()
            if wall >= next_hb:
                next_hb = max(next_hb + 1.0 / self.heartbeat_hz, wall - 1.0)
                self._heartbeat()
            now_s = self.time_boot_ms / 1000.0
            self._physics(max(0.0, now_s - last_s))
            last_s = now_s
            self._send_streams(now_s)

    def _send(self, msg: Any) -> None:
        self._conn.mav.send(msg)
        self.sent[msg.get_type()] += 1

    def _heartbeat(self) -> None:
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (M.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        state = M.MAV_STATE_ACTIVE if self.armed else M.MAV_STATE_STANDBY
        self._send(M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base,
                                               self.mode, state, 3))

    def _send_streams(self, now_s: float) -> None:
        with self._lock:
            outbox, self._outbox = self._outbox, []
            due = []
            for name, interval in self._intervals.items():
                if now_s >= self._due.get(name, 0.0):
                    nxt = self._due.get(name, now_s) + interval
                    self._due[name] = nxt if nxt > now_s else now_s + interval
                    due.append(name)
        for name in outbox + due:
            msg = self._builders[name]()
            if msg is not None:
                self._send(msg)

    def _physics(self, dt: float) -> None:
        x, y, z = self.position
        if not self.armed or self.mode != GUIDED:
            self._climb_to = None
        if self._climb_to is None and self.mode != LAND:
            return
        if self._climb_to is not None:
            z = max(self._climb_to, z - dt)
            self.velocity = (0.0, 0.0, -1.0 if z > self._climb_to else 0.0)
            if z <= self._climb_to:
                self._climb_to = None
        elif not self.landed:
            z = min(0.0, z + dt)
            self.velocity = (0.0, 0.0, 1.0 if z < 0.0 else 0.0)
            if z >= 0.0:
                self.landed, self.armed = True, False
        else:
            return
        self.position = (x, y, z)
        if z < -0.1:
            self.landed = False

    # --- receiving ---------------------------------------------------------------------------------------
    def _handle(self, msg: Any) -> None:
        t = msg.get_type()
        if t == "BAD_DATA":
            return
        with self._lock:
            self.received.append(Received(msg, time.monotonic(), self.time_boot_ms))
        if t == "COMMAND_LONG" and msg.target_system in (0, 1):
            self._command(msg)
        elif t == "REQUEST_DATA_STREAM":
            self._request_data_stream(msg)
        elif t == "SET_POSITION_TARGET_LOCAL_NED" and self.mode == GUIDED and self.armed and not self.landed:
            self.target = msg
            self._climb_to = None
            if not msg.type_mask & _POS_IGNORED:
                self.position = (msg.x, msg.y, msg.z)

    def _command(self, msg: Any) -> None:
        fn = self.policy.get(msg.command)
        result = fn(msg) if fn is not None else M.MAV_RESULT_ACCEPTED
        if result == M.MAV_RESULT_ACCEPTED:
            result = self._effect(msg)
        if result is not None:
            self.acks.append((msg.command, result))
            self._send(M.MAVLink_command_ack_message(msg.command, result, 0, 0, msg.get_srcSystem(),
                                                     msg.get_srcComponent()))

    def _effect(self, m: Any) -> int:
        """The default effect of an accepted command; its MAV_RESULT."""
        c = m.command
        if c == M.MAV_CMD_DO_SET_MODE:
            self.mode = int(m.param2)
        elif c == M.MAV_CMD_COMPONENT_ARM_DISARM:
            if round(m.param1) == 1:
                self.armed = True
            elif not self.landed and round(m.param2) != FORCE_DISARM:
                return M.MAV_RESULT_FAILED
            else:
                self.armed = False
        elif c == M.MAV_CMD_NAV_TAKEOFF:
            if not (self.armed and self.landed and self.mode == GUIDED) or m.param7 <= 0:
                return M.MAV_RESULT_FAILED
            self._climb_to = -float(m.param7)
        elif c == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            if not self.message_interval_supported:
                return M.MAV_RESULT_UNSUPPORTED
            name = self._name(m.param1)
            if name is None:
                return M.MAV_RESULT_DENIED
            us = m.param2  # -1 off, 0 the default rate
            self._set_interval(name, None if us < 0 else 0.25 if us == 0 else us * 1e-6)
        elif c == M.MAV_CMD_REQUEST_MESSAGE:
            name = self._name(m.param1)
            if name is None:
                return M.MAV_RESULT_DENIED
            with self._lock:
                self._outbox.append(name)
        return M.MAV_RESULT_ACCEPTED

    def _name(self, msg_id: float) -> str | None:
        cls = M.mavlink_map.get(int(msg_id))
        name = cls.msgname if cls is not None else None
        return name if name in self._builders else None

    def _set_interval(self, name: str, interval_s: float | None) -> None:
        with self._lock:
            if interval_s is None:
                self._intervals.pop(name, None)
            else:
                self._intervals[name] = interval_s
            self._due.pop(name, None)

    def _request_data_stream(self, m: Any) -> None:
        self.data_stream_requests.append(DataStreamRequest(m.req_stream_id, m.req_message_rate,
                                                           bool(m.start_stop)))
        groups = list(STREAM_GROUPS) if m.req_stream_id == M.MAV_DATA_STREAM_ALL else [m.req_stream_id]
        on = bool(m.start_stop) and m.req_message_rate > 0
        for g in groups:
            for name in STREAM_GROUPS.get(g, ()):
                self._set_interval(name, 1.0 / m.req_message_rate if on else None)

    # --- messages ----------------------------------------------------------------------------------------
    def _latlon(self) -> tuple[int, int]:
        x, y, _ = self.position
        lat = self.home[0] + math.degrees(x / 6378137.0)
        lon = self.home[1] + math.degrees(y / (6378137.0 * math.cos(math.radians(self.home[0]))))
        return int(lat * 1e7), int(lon * 1e7)

    def _local_position(self) -> Any:
        return M.MAVLink_local_position_ned_message(self.time_boot_ms, *self.position, *self.velocity)

    def _distance_sensor(self) -> Any:
        """A downward range finder over flat ground at home's height (cm, rotation PITCH_270)."""
        cm = int(max(0.0, min(655.35, -self.position[2])) * 100)
        return M.MAVLink_distance_sensor_message(self.time_boot_ms, 20, 4000, cm, M.MAV_DISTANCE_SENSOR_LASER,
                                                 0, M.MAV_SENSOR_ROTATION_PITCH_270, 0, 0.0, 0.0,
                                                 [0.0, 0.0, 0.0, 0.0], 0)

    def _attitude(self) -> Any:
        return M.MAVLink_attitude_message(self.time_boot_ms, 0.0, 0.0, self.yaw, 0.0, 0.0, 0.0)

    def _extended_sys_state(self) -> Any:
        landed = M.MAV_LANDED_STATE_ON_GROUND if self.landed else M.MAV_LANDED_STATE_IN_AIR
        return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_UNDEFINED, landed)

    def _global_position(self) -> Any:
        lat, lon = self._latlon()
        rel = -self.position[2] + self.home_offset_m
        vx, vy, vz = (int(v * 100) for v in self.velocity)
        hdg = int(math.degrees(self.yaw) % 360.0 * 100)
        return M.MAVLink_global_position_int_message(self.time_boot_ms, lat, lon,
                                                     int((self.home[2] + rel) * 1000), int(rel * 1000),
                                                     vx, vy, vz, hdg)

    def _sys_status(self) -> Any:
        return M.MAVLink_sys_status_message(_SENSORS, _SENSORS, _SENSORS, 100, 12600, 1000, 80,
                                            0, 0, 0, 0, 0, 0, 0, 0, 0)

    def _battery_status(self) -> Any:
        """As SYS_STATUS: 10 A drawn, 80 % left (1000 mAh used of a 5000 mAh pack)."""
        return M.MAVLink_battery_status_message(0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 32767,
                                                [12600] + [65535] * 9, 1000, 1000, -1, 80)

    def _home_position(self) -> Any:
        lat, lon, alt = self.home
        return M.MAVLink_home_position_message(int(lat * 1e7), int(lon * 1e7), int(alt * 1000), 0.0, 0.0,
                                               self.home_offset_m, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0)

    def _rc_channels(self) -> Any:
        return M.MAVLink_rc_channels_message(self.time_boot_ms, 16, *list(self.rc)[:18], 255)

    def _gps_raw(self) -> Any:
        lat, lon = self._latlon()
        alt = int((self.home[2] + self.home_offset_m - self.position[2]) * 1000)
        return M.MAVLink_gps_raw_int_message(self.time_boot_ms * 1000, 3, lat, lon, alt, 80, 120, 0, 0, 12)

    def _system_time(self) -> Any:
        return M.MAVLink_system_time_message(int(time.time() * 1e6), self.time_boot_ms)

    def _position_target(self) -> Any:
        t = self.target
        if t is None:
            return None
        return M.MAVLink_position_target_local_ned_message(self.time_boot_ms, t.coordinate_frame, t.type_mask,
                                                           t.x, t.y, t.z, t.vx, t.vy, t.vz, t.afx, t.afy,
                                                           t.afz, t.yaw, t.yaw_rate)
