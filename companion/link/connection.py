"""The MAVLink link to the autopilot (seed 000 Fig. 10, the QuadNode-firmware link).

:class:`MavlinkLink` opens one pymavlink connection (ardupilotmega dialect, MAVLink 2) on

* ``udpin:HOST:PORT`` (listen; the autopilot sends first), ``udpout:HOST:PORT`` (send to a listening
  autopilot, e.g. ArduPilot SITL's or the model's ``udpin:0.0.0.0:14550``), ``tcp:HOST:PORT``,
* a serial port: ``serial:/dev/ttyUSB0:921600``, ``/dev/ttyACM0`` or ``COM3`` (pyserial; baud rate
  from the URL or ``baud``),

and runs one receive thread, the only writer of the :class:`~companion.link.mirror.VehicleMirror`
and the feeder of the :class:`~companion.link.clock.AutopilotClock`. Everything that sends
(heartbeat, stream requests, command retries, setpoints) is driven by :meth:`MavlinkLink.periodic`
and the ``send_*`` methods, called from the node's tick thread; a lock serialises the socket.

Identity: our HEARTBEAT says MAV_TYPE_ONBOARD_CONTROLLER / MAV_AUTOPILOT_INVALID from component
MAV_COMP_ID_ONBOARD_COMPUTER (191). The system id is, by MAVLink convention for components of one
vehicle, the autopilot's own (adopted from its first heartbeat) unless ``source_system`` is given.
ArduCopter's GCS failsafe counts heartbeats from system MAV_GCS_SYSID (SYSID_MYGCS, 255) only, so
the companion's heartbeat never keeps the GCS failsafe quiet.

Streams: MAV_CMD_SET_MESSAGE_INTERVAL per message, one at a time (ACKs carry no message id); if
the autopilot does not support it (UNSUPPORTED or no ACK before any was accepted) the link falls back
to REQUEST_DATA_STREAM with ArduCopter's stream groups; a message refused after others were accepted
is only skipped (the model has no RC_CHANNELS). Requested again whenever the autopilot reappears.
"""

from __future__ import annotations

import logging
import os
import select
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
import contextlib

from pymavlink import mavutil

from companion.flight.setpoint import Setpoint

from .clock import AutopilotClock
from .commands import CommandRequest, CommandState, CommandTracker
from .mirror import VehicleMirror
from .setpoints import SyncTracker, TargetFields, target_fields

log = logging.getLogger(__name__)
M = mavutil.mavlink

#: A link is "connected" while autopilot heartbeats arrive at least this often (wall seconds).
LINK_TIMEOUT_WALL_S = 3.0
#: Messages whose time_boot_ms feeds the clock.
_TIMED = frozenset({"LOCAL_POSITION_NED", "ATTITUDE", "SYSTEM_TIME", "GLOBAL_POSITION_INT",
                    "POSITION_TARGET_LOCAL_NED", "RC_CHANNELS", "DISTANCE_SENSOR"})


def parse_url(url: str, baud: int) -> tuple[str, int]:
    """(pymavlink device string, baud) for our URL forms (see module docstring)."""
    if url.startswith("serial:"):
        rest = url[len("serial:"):]
        dev, _, b = rest.rpartition(":") if rest.count(":") >= 1 and rest.rsplit(":", 1)[1].isdigit() \
            else (rest, "", "")
        return dev, int(b) if b else baud
    if url.startswith(("udpin:", "udpout:", "udp:", "tcp:", "tcpin:", "udpbcast:")):
        return url, baud
    if url.startswith("/dev/") or url.upper().startswith("COM"):
        return url, baud
    raise ValueError(f"--autopilot {url!r}: expected udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or "
                     "serial:DEVICE[:BAUD]")


def stream_plan(rate_hz: float) -> list[tuple[int, float]]:
    """(message id, Hz) the companion asks for: its tick needs LOCAL_POSITION_NED at the stream rate."""
    return [
        (M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, max(10.0, rate_hz)),
        (M.MAVLINK_MSG_ID_ATTITUDE, 10.0),
        (M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 5.0),
        (M.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED, 10.0),
        (M.MAVLINK_MSG_ID_SYS_STATUS, 2.0),
        (M.MAVLINK_MSG_ID_BATTERY_STATUS, 1.0),
        (M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 5.0),
        (M.MAVLINK_MSG_ID_GPS_RAW_INT, 2.0),
        (M.MAVLINK_MSG_ID_SYSTEM_TIME, 2.0),
        (M.MAVLINK_MSG_ID_HOME_POSITION, 0.5),
        (M.MAVLINK_MSG_ID_RC_CHANNELS, 10.0),
        # the downward range finder (follow-ground flight); an autopilot without one sends none
        (M.MAVLINK_MSG_ID_DISTANCE_SENSOR, 10.0),
    ]


#: REQUEST_DATA_STREAM fallback: ArduCopter's groups holding the messages above.
FALLBACK_GROUPS = ((M.MAV_DATA_STREAM_POSITION, None), (M.MAV_DATA_STREAM_EXTRA1, 10),
                   (M.MAV_DATA_STREAM_EXTENDED_STATUS, 5), (M.MAV_DATA_STREAM_EXTRA3, 2),
                   (M.MAV_DATA_STREAM_RC_CHANNELS, 10))


class MavlinkLink:
    """One MAVLink connection to one autopilot (see module docstring)."""

    def __init__(self, url: str, *, baud: int = 57600, rate_hz: float = 20.0,
                 source_system: int | None = None,
                 source_component: int = M.MAV_COMP_ID_ONBOARD_COMPUTER, clock: AutopilotClock | None = None,
                 command_timeout_s: float = 1.0, command_attempts: int = 3) -> None:
        self.url = url
        self.device, self.baud = parse_url(url, baud)
        self.rate_hz = rate_hz
        self.clock = clock or AutopilotClock()
        self.mirror = VehicleMirror()
        self.sync = SyncTracker()
        self.stats: Counter[str] = Counter()
        self._source_system = source_system
        self._source_component = source_component
        self.target_system: int | None = None
        self.target_component: int | None = None
        self.commands = CommandTracker(self._send_command, command_timeout_s, command_attempts)
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._conn: Any = None
        self._wall = time.monotonic
        self._next_hb_s: float | None = None
        self._streams_wanted = False
        self._stream_queue: list[tuple[int, float]] = []
        self._stream_req: CommandRequest | None = None
        self.streams_mode = "none"  # none / message_interval / data_stream
        self._interval_accepted = False
        self._last_hb_wall: float | None = None
        self.new_data = threading.Event()
        self.listeners: list[Callable[[Any], None]] = []

    # --- lifecycle -------------------------------------------------------------------------------------
    def start(self) -> None:
        mavutil.set_dialect("ardupilotmega")
        self._conn = mavutil.mavlink_connection(
            self.device, baud=self.baud, source_system=self._source_system or 1,
            source_component=self._source_component, dialect="ardupilotmega", autoreconnect=True)
        self._conn.mav.WIRE_PROTOCOL_VERSION = "2.0"
        self._thread = threading.Thread(target=self._receive_loop, name="mavlink-rx", daemon=True)
        self._thread.start()
        log.info("MAVLink link on %s", self.url)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._conn is not None:
            with contextlib.suppress(OSError):
                self._conn.close()

    @property
    def connected(self) -> bool:
        last = self._last_hb_wall
        return last is not None and self._wall() - last <= LINK_TIMEOUT_WALL_S

    # --- receiving (the receive thread owns the mirror) --------------------------------------------------
    def _receive_loop(self) -> None:
        read = self._read_datagram if isinstance(self._conn, mavutil.mavudp) else self._read_message
        while not self._stop.is_set():
            try:
                msgs = read()
            except (OSError, ValueError) as exc:
                if self._stop.is_set():
                    return
                self.stats["rx_error"] += 1
                log.debug("receive error: %s", exc)
                self._stop.wait(0.05)
                continue
            for msg in msgs:
                try:
                    self._handle(msg)
                except Exception:  # one bad message never stops the link
                    self.stats["rx_handler_error"] += 1
                    log.exception("handling %s failed", msg.get_type())

    def _read_message(self) -> list[Any]:
        """TCP and serial: the next message (a byte stream), or none within 0.1 s."""
        msg = self._conn.recv_match(blocking=True, timeout=0.1)
        return [] if msg is None else [msg]

    def _read_datagram(self) -> list[Any]:
        """The UDP forms: one datagram read by pymavlink's own ``recv`` (which records the sender a
        ``udpin:`` link answers) and parsed whole by ``parse_buffer``, or none within 0.1 s. ``recv_match``
        would do the same with two reads, a select and its per-message bookkeeping (sequence loss,
        per-system tables) for each message, and an autopilot sends several messages to a datagram."""
        conn = self._conn
        if not select.select([conn.port], [], [], 0.1)[0]:
            return []
        data = conn.recv()
        return (conn.mav.parse_buffer(data) or []) if data else []

    def _handle(self, msg: Any) -> None:
        t = msg.get_type()
        if t == "BAD_DATA":
            self.stats["rx_bad"] += 1
            return
        wall = self._wall()
        src, comp = msg.get_srcSystem(), msg.get_srcComponent()
        if t == "HEARTBEAT" and self.target_system is None and msg.autopilot != M.MAV_AUTOPILOT_INVALID \
                and msg.type not in (M.MAV_TYPE_GCS, M.MAV_TYPE_ONBOARD_CONTROLLER):
            self.target_system, self.target_component = src, comp
            if self._source_system is None:
                self._conn.mav.srcSystem = src
            log.info("autopilot: system %d component %d", src, comp)
        if src != self.target_system or comp != self.target_component:
            self.stats["rx_other"] += 1
            return
        self.stats["rx"] += 1
        if t == "HEARTBEAT":
            gap = self._last_hb_wall is None or wall - self._last_hb_wall > LINK_TIMEOUT_WALL_S
            self._last_hb_wall = wall
            if gap:
                self._streams_wanted = True
        if t in _TIMED:
            self.clock.observe(msg.time_boot_ms, wall)
        if t == "COMMAND_ACK":
            self.commands.on_ack(msg)
        self.mirror.update(msg, wall)
        if t == "POSITION_TARGET_LOCAL_NED":
            echo = self.mirror.snapshot().position_target
            if echo is not None:
                self.sync.echo(echo, self.clock.now())
        for fn in self.listeners:
            fn(msg)
        self.new_data.set()

    # --- sending (tick thread) -----------------------------------------------------------------------------
    def _target(self) -> tuple[int, int]:
        return self.target_system or 1, self.target_component or 1

    def _send_command(self, command: int, confirmation: int, params: tuple[float, ...]) -> None:
        ts, tc = self._target()
        with self._send_lock:
            self._conn.mav.command_long_send(ts, tc, command, confirmation, *params)
        self.stats["tx_command"] += 1

    def periodic(self, now_s: float) -> None:
        """Heartbeat at 1 Hz (autopilot time), command retries, stream requests."""
        if self._conn is None:
            return
        if self._next_hb_s is None or now_s >= self._next_hb_s or now_s < self._next_hb_s - 1.0:
            self._next_hb_s = now_s + 1.0
            with self._send_lock:
                self._conn.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                              M.MAV_STATE_ACTIVE)
            self.stats["tx_heartbeat"] += 1
        self.commands.periodic(now_s)
        self._streams(now_s)

    def _streams(self, now_s: float) -> None:
        if self._streams_wanted and self.target_system is not None:
            self._streams_wanted = False
            self._stream_queue = stream_plan(self.rate_hz)
            self._stream_req = None
            self._interval_accepted = False
            self.streams_mode = "message_interval"
            self.commands.request(M.MAV_CMD_REQUEST_MESSAGE, (M.MAVLINK_MSG_ID_HOME_POSITION,), now_s)
        req = self._stream_req
        if req is not None and not req.done:
            return
        if req is not None and req.accepted:
            self._interval_accepted = True
        refused = req is not None and (req.state is CommandState.TIMEOUT
                                       or req.result == M.MAV_RESULT_UNSUPPORTED)
        if refused and not self._interval_accepted:
            self._fallback_streams()  # the autopilot does not know SET_MESSAGE_INTERVAL at all
            return
        if req is not None and (refused or not req.accepted):
            # it knows the command but not this message (the model has no RC_CHANNELS): skip it only
            log.info("stream %s refused (%s); the other streams stay", req.params[0], req.describe())
        if not self._stream_queue:
            self._stream_req = None
            return
        msg_id, hz = self._stream_queue.pop(0)
        self._stream_req = self.commands.request(M.MAV_CMD_SET_MESSAGE_INTERVAL, (msg_id, 1e6 / hz), now_s)

    def _fallback_streams(self) -> None:
        log.warning("SET_MESSAGE_INTERVAL not supported: falling back to REQUEST_DATA_STREAM")
        self._stream_queue = []
        self._stream_req = None
        self.streams_mode = "data_stream"
        ts, tc = self._target()
        with self._send_lock:
            for stream_id, hz in FALLBACK_GROUPS:
                rate = round(max(10.0, self.rate_hz)) if hz is None else hz
                self._conn.mav.request_data_stream_send(ts, tc, stream_id, rate, 1)

    def send_setpoint(self, sp: Setpoint, now_s: float) -> TargetFields:
        """One SET_POSITION_TARGET_LOCAL_NED in MAV_FRAME_LOCAL_NED (masks: :mod:`.setpoints`)."""
        f = target_fields(sp)
        ts, tc = self._target()
        with self._send_lock:
            self._conn.mav.set_position_target_local_ned_send(
                int(now_s * 1000) & 0xFFFFFFFF, ts, tc, M.MAV_FRAME_LOCAL_NED, f.type_mask,
                *f.p, *f.v, *f.a, f.yaw, f.yaw_rate)
        self.stats["tx_setpoint"] += 1
        self.sync.sent(now_s, f)
        return f

    def send_param_set(self, name: str, value: float, param_type: int) -> None:
        """PARAM_SET (the parameter protocol; :mod:`.params` waits for the autopilot's PARAM_VALUE)."""
        ts, tc = self._target()
        with self._send_lock:
            self._conn.mav.param_set_send(ts, tc, name.encode("ascii"), float(value), param_type)
        self.stats["tx_param"] += 1

    def send_param_request(self, name: str) -> None:
        """PARAM_REQUEST_READ by name (index -1)."""
        ts, tc = self._target()
        with self._send_lock:
            self._conn.mav.param_request_read_send(ts, tc, name.encode("ascii"), -1)
        self.stats["tx_param"] += 1

    def addressed_to_us(self, msg: Any) -> bool:
        """Whether ``msg`` (a targeted message) is for this companion: our system id and our component, or
        a broadcast (0)."""
        ts, tc = getattr(msg, "target_system", 0), getattr(msg, "target_component", 0)
        return ts in (0, self._conn.mav.srcSystem) and tc in (0, self._source_component)

    def send_mission_count(self, count: int, mission_type: int) -> None:
        """MISSION_COUNT: an upload of ``count`` items of ``mission_type`` begins (:mod:`.fence` answers the
        autopilot's requests)."""
        ts, tc = self._target()
        with self._send_lock:
            self._conn.mav.mission_count_send(ts, tc, count, mission_type)
        self.stats["tx_mission"] += 1

    def send_mission_item_int(self, seq: int, frame: int, command: int,
                              params: tuple[float, float, float, float], lat: float, lon: float, alt: float,
                              mission_type: int) -> None:
        """MISSION_ITEM_INT ``seq`` (latitude and longitude in degrees, sent as degrees * 1e7)."""
        ts, tc = self._target()
        with self._send_lock:
            self._conn.mav.mission_item_int_send(ts, tc, seq, frame, command, 0, 0, *params,
                                                 round(lat * 1e7), round(lon * 1e7), alt, mission_type)
        self.stats["tx_mission"] += 1

    # --- vehicle commands ---------------------------------------------------------------------------
    def set_mode(self, custom_mode: int, now_s: float) -> CommandRequest:
        """MAV_CMD_DO_SET_MODE with an ArduCopter custom mode (GUIDED 4, LAND 9 ...)."""
        return self.commands.request(M.MAV_CMD_DO_SET_MODE,
                                     (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode), now_s)

    def arm(self, now_s: float) -> CommandRequest:
        return self.commands.request(M.MAV_CMD_COMPONENT_ARM_DISARM, (1,), now_s)

    def disarm(self, now_s: float) -> CommandRequest:
        """Disarm (ArduCopter refuses it in the air unless forced; we never force)."""
        return self.commands.request(M.MAV_CMD_COMPONENT_ARM_DISARM, (0,), now_s)

    def takeoff(self, altitude_above_home_m: float, now_s: float) -> CommandRequest:
        """MAV_CMD_NAV_TAKEOFF: ArduCopter (GUIDED, armed, on the ground) climbs to param7 m above home."""
        return self.commands.request(M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0,
                                                              altitude_above_home_m), now_s)

    def status(self) -> dict[str, Any]:
        return {"url": self.url, "connected": self.connected, "target_system": self.target_system,
                "clock_synced": self.clock.synced, "clock_rate": round(self.clock.rate, 3),
                "autopilot_time_s": round(self.clock.now(), 3), "streams": self.streams_mode,
                "pending_commands": self.commands.pending, "command_errors": list(self.commands.errors),
                "stats": dict(self.stats)}
