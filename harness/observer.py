"""The ground-station observer: :class:`Gcs`, a pymavlink ground station (system 255 unless told
otherwise, optionally signing) that sends GCS heartbeats while it pumps and records what the vehicle
sends; the ArduCopter flight-mode numbers and SET_POSITION_TARGET type masks the tests send with it."""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil

from harness.timing import SPEEDUP, wait_for, wall
from taskflight_common.ardupilot import CopterMode

mavutil.set_dialect("ardupilotmega")

M = mavutil.mavlink
#: ArduCopter flight modes (HEARTBEAT custom_mode)
STABILIZE, ALT_HOLD, AUTO, GUIDED, LOITER, RTL, LAND, BRAKE = (
    CopterMode.STABILIZE, CopterMode.ALT_HOLD, CopterMode.AUTO, CopterMode.GUIDED, CopterMode.LOITER,
    CopterMode.RTL, CopterMode.LAND, CopterMode.BRAKE)
#: SET_POSITION_TARGET_* type masks: position only, velocity only
POS_ONLY = 0b110111111000
VEL_ONLY = 0b110111000111


class Gcs:
    """A pymavlink ground station on ``udpout:127.0.0.1:port`` (or ``url``, e.g. ``udpin:`` for ArduCopter
    SITL's ``udpclient`` serial ports).

    It sends MAV_TYPE_GCS heartbeats at ``heartbeat_hz`` of simulated time while ``heartbeats`` is set
    and records what it receives: the last message of each type (``last``), STATUSTEXTs (``texts``),
    COMMAND_ACKs (``acks``), PARAM_VALUEs (``params``: value, index by name), the MISSION_* protocol
    messages in order (``mission``), MISSION_ITEM_REACHED seqs (``reached``), the vehicle's mode changes
    (``modes_seen``) and LOCAL_POSITION_NED positions (``positions``).

    By default it pumps only inside :meth:`wait` (and the helpers built on it) or :meth:`pump`; with
    ``background=True`` a thread pumps all the time (for tests that wait on something else) and
    :meth:`pump` does nothing. ``key`` signs what it sends (MAVLink 2 signing). ``target`` is the
    vehicle's system id (1 unless it is one of a fleet's, :mod:`autopilot_model.fleet`).
    """

    def __init__(self, port: int, speedup: float = SPEEDUP, *, sysid: int = 255, key: bytes | None = None,
                 heartbeat_hz: float = 1.0, background: bool = False, url: str | None = None,
                 target: int = 1) -> None:
        mavutil.set_dialect("ardupilotmega")
        self.conn = mavutil.mavlink_connection(url or f"udpout:127.0.0.1:{port}", source_system=sysid,
                                               source_component=190)
        if key is not None:
            self.conn.setup_signing(key, sign_outgoing=True)
        self.speedup = speedup
        self.target = target
        self.heartbeats = threading.Event()
        self.heartbeats.set()
        self.last: dict[str, Any] = {}
        self.texts: list[str] = []
        self.acks: list[Any] = []
        self.params: dict[str, tuple[float, int]] = {}
        self.mission: list[Any] = []  # MISSION_* messages from the vehicle, in order
        self.reached: list[int] = []
        self.modes_seen: list[int] = []
        self.positions: list[tuple[float, float, float]] = []
        self._hb_period = 1.0 / (heartbeat_hz * speedup)
        self._hb_t = 0.0
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if background:
            self._thread = threading.Thread(target=self._run, name="gcs", daemon=True)
            self._thread.start()

    # --- receiving -----------------------------------------------------------------------------------
    def _heartbeat_if_due(self) -> None:
        now = time.monotonic()
        if now - self._hb_t > self._hb_period:
            self._hb_t = now
            if self.heartbeats.is_set():
                self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def _record(self, m: Any) -> None:
        t = m.get_type()
        with self._lock:
            self.last[t] = m
            if t == "STATUSTEXT":
                self.texts.append(m.text)
            elif t == "COMMAND_ACK":
                self.acks.append(m)
            elif t == "PARAM_VALUE":
                self.params[m.param_id] = (m.param_value, m.param_index)
            elif t == "MISSION_ITEM_REACHED":
                self.reached.append(m.seq)
            elif t.startswith("MISSION_") and t != "MISSION_CURRENT":
                self.mission.append(m)
            elif t == "HEARTBEAT" and m.get_srcSystem() == self.target:
                if not self.modes_seen or self.modes_seen[-1] != m.custom_mode:
                    self.modes_seen.append(m.custom_mode)
            elif t == "LOCAL_POSITION_NED":
                self.positions.append((m.x, m.y, m.z))

    def _run(self) -> None:
        while not self._stop.is_set():
            self._heartbeat_if_due()
            m = self.conn.recv_match(blocking=True, timeout=0.02)
            while m is not None:
                self._record(m)
                m = self.conn.recv_match(blocking=False)

    def pump(self) -> None:
        """Heartbeat if due, then record everything received (a no-op with ``background``)."""
        if self._thread is not None:
            return
        self._heartbeat_if_due()
        while (m := self.conn.recv_match(blocking=False)) is not None:
            self._record(m)

    def wait(self, pred: Callable[[], Any], timeout_s: float, what: str) -> Any:
        """Pump and test ``pred`` until truthy; AssertionError with the last STATUSTEXTs at the deadline."""
        def pumped() -> Any:
            self.pump()
            return pred()

        try:
            return wait_for(pumped, timeout_s, what, poll_s=0.002)
        except AssertionError as exc:
            raise AssertionError(f"{exc}; last texts {self.texts[-6:]}") from None

    def msg(self, t: str, timeout_s: float = 10.0) -> Any:
        """The last message of type ``t`` (waiting for the first one)."""
        return self.wait(lambda: self.last.get(t), timeout_s, t)

    def fresh(self, t: str, timeout_s: float = 5.0) -> Any:
        """The next message of type ``t``."""
        with self._lock:
            self.last.pop(t, None)
        return self.wait(lambda: self.last.get(t), timeout_s, t)

    def next_mission(self, types: tuple[str, ...], timeout_s: float = 5.0) -> Any:
        """The first recorded MISSION_* message of one of ``types``; it and those before it are consumed."""
        def first() -> Any:
            with self._lock:
                for i, m in enumerate(self.mission):
                    if m.get_type() in types:
                        del self.mission[: i + 1]
                        return m
            return None
        return self.wait(first, timeout_s, "/".join(types))

    # --- commands and parameters ---------------------------------------------------------------------
    def command_ack(self, cmd: int, *p: float, timeout_s: float = 10.0) -> Any:
        """COMMAND_LONG to the vehicle; returns its COMMAND_ACK."""
        params = list(p) + [0.0] * (7 - len(p))
        with self._lock:
            self.acks.clear()
        self.conn.mav.command_long_send(self.target, 1, cmd, 0, *params)

        def ack() -> Any:
            with self._lock:
                return next((a for a in self.acks if a.command == cmd), None)

        return self.wait(ack, timeout_s, f"ACK of {cmd}")

    def command(self, cmd: int, *p: float, timeout_s: float = 10.0) -> int:
        """COMMAND_LONG to the vehicle; returns the ACK's result."""
        return self.command_ack(cmd, *p, timeout_s=timeout_s).result

    def set_mode(self, mode: int) -> int:
        return self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)

    def set_param(self, name: str, value: float, timeout_s: float = 10.0) -> None:
        """PARAM_SET; returns when the vehicle echoes the new value."""
        with self._lock:
            self.last.pop("PARAM_VALUE", None)
        self.conn.mav.param_set_send(self.target, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32)

        def echoed() -> bool:
            m = self.last.get("PARAM_VALUE")
            return m is not None and m.param_id == name and math.isclose(m.param_value, value, rel_tol=1e-6,
                                                                         abs_tol=1e-4)

        self.wait(echoed, timeout_s, f"PARAM_VALUE {name}={value}")

    def param(self, name: str, timeout_s: float = 10.0) -> float:
        """The autopilot's value of ``name`` now (PARAM_REQUEST_READ, answered by PARAM_VALUE)."""
        with self._lock:
            self.last.pop("PARAM_VALUE", None)
        self.conn.mav.param_request_read_send(self.target, 1, name.encode(), -1)
        def answered() -> Any:
            p = self.last.get("PARAM_VALUE")
            return p if p is not None and p.param_id == name else None

        m: Any = self.wait(answered, timeout_s, f"PARAM_VALUE {name}")
        return float(m.param_value)

    def request_streams(self, hz: int) -> None:
        """REQUEST_DATA_STREAM for every group (ArduCopter streams on a fresh link only when asked)."""
        self.conn.mav.request_data_stream_send(self.target, 1, M.MAV_DATA_STREAM_ALL, hz, 1)

    def local_target(self, frame: int, mask: int, x: float = 0, y: float = 0, z: float = 0,
                     vx: float = 0, vy: float = 0, vz: float = 0) -> None:
        self.conn.mav.set_position_target_local_ned_send(0, self.target, 1, frame, mask, x, y, z, vx, vy, vz,
                                                         0, 0, 0, 0, 0)

    # --- the vehicle's state -------------------------------------------------------------------------
    def heartbeat(self) -> Any:
        """The vehicle's next HEARTBEAT."""
        return self.wait(lambda: (m := self.fresh("HEARTBEAT")) and m.get_srcSystem() == self.target and m, 5,
                         "HB")

    def mode(self) -> int:
        return self.heartbeat().custom_mode

    def armed(self) -> bool:
        return bool(self.heartbeat().base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)

    def ned(self) -> tuple[float, float, float]:
        m = self.fresh("LOCAL_POSITION_NED")
        return m.x, m.y, m.z

    def home(self) -> tuple[float, float, float]:
        """Home as latitude, longitude (degrees), altitude AMSL (m)."""
        h = self.fresh("HOME_POSITION", 10)
        return h.latitude * 1e-7, h.longitude * 1e-7, h.altitude * 1e-3

    def wall(self, sim_s: float) -> float:
        return wall(sim_s, self.speedup)

    def wait_prearm(self, timeout_s: float) -> None:
        self.wait(lambda: (m := self.last.get("SYS_STATUS")) is not None
                  and m.onboard_control_sensors_health & M.MAV_SYS_STATUS_PREARM_CHECK,
                  timeout_s, "pre-arm checks to pass")

    def at(self, target: tuple[float, float, float], tol: float, sim_s: float) -> None:
        """Wait until within ``tol`` m of the local NED ``target``."""
        def close() -> bool:
            m = self.last.get("LOCAL_POSITION_NED")
            return m is not None and math.dist((m.x, m.y, m.z), target) < tol
        with self._lock:
            self.last.pop("LOCAL_POSITION_NED", None)
        self.wait(close, self.wall(sim_s), f"position {target}")

    def wait_alt(self, alt: float, sim_s: float, tol: float = 0.5) -> None:
        self.wait(lambda: (m := self.last.get("LOCAL_POSITION_NED")) is not None and abs(-m.z - alt) < tol,
                  self.wall(sim_s), f"altitude {alt}")

    def wait_mode(self, mode: int, sim_s: float) -> None:
        self.wait(lambda: mode in self.modes_seen[-1:], self.wall(sim_s), f"mode {mode}")

    def wait_disarmed(self, sim_s: float) -> None:
        self.wait(lambda: (m := self.last.get("HEARTBEAT")) is not None
                  and not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, self.wall(sim_s), "disarmed")

    def wait_autopilot_disarmed(self, timeout_s: float) -> None:
        """The autopilot's own HEARTBEAT says disarmed: ArduCopter routes a companion's heartbeats (same
        system id) to this station too; those are told apart by their MAV_AUTOPILOT_INVALID."""
        def disarmed() -> bool:
            m = self.last.get("HEARTBEAT")
            return (m is not None and m.autopilot != M.MAV_AUTOPILOT_INVALID
                    and not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        self.wait(disarmed, timeout_s, "the autopilot disarmed")

    # --- flying --------------------------------------------------------------------------------------
    def takeoff(self, alt: float) -> None:
        """GUIDED, arm, take off; returns when at altitude."""
        assert self.set_mode(GUIDED) == M.MAV_RESULT_ACCEPTED
        self.wait(lambda: self.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED,
                  self.wall(20), "arming")
        assert self.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, alt) == M.MAV_RESULT_ACCEPTED
        self.wait_alt(alt, 30)

    def land_and_disarm(self) -> None:
        assert self.set_mode(LAND) == M.MAV_RESULT_ACCEPTED
        self.wait_disarmed(90)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        self.conn.close()
