"""Helpers for the companion's integration tests and bench (no tests here).

* :class:`WireTap`: a UDP relay between the companion and the model that decodes what the companion
  sends, so tests count SET_POSITION_TARGET_LOCAL_NED *on the wire*;
* :class:`Gcs`: a pymavlink ground station (system 255, MAV_TYPE_GCS heartbeats at 1 Hz of simulated
  time) in a background thread, for mode changes, parameters and observing the vehicle;
* :func:`cmd`: a flight command from plain data (the codec form the HTTP surface takes).
"""

from __future__ import annotations

import math
import os
import select
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from companion.flight import FlightCommand, command_from_dict

M = mavutil.mavlink


def cmd(data: dict[str, Any]) -> FlightCommand:
    return command_from_dict(data)


class WireTap:
    """Relay ``127.0.0.1:port`` <-> the model's udpin port; counts message types the companion sends."""

    def __init__(self, model_port: int, record: str | None = None) -> None:
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind(("127.0.0.1", 0))
        self.port = self.front.getsockname()[1]
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.connect(("127.0.0.1", model_port))
        self.sent: Counter[str] = Counter()
        #: wall arrival times of each message of type ``record`` (for the bench's jitter)
        self.record = record
        self.times: list[float] = []
        self._parser = mavlink2.MAVLink(None)
        self._parser.robust_parsing = True
        self._client: tuple[str, int] | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name="wiretap", daemon=True)
        self._thread.start()

    def count(self, msg_type: str) -> int:
        with self._lock:
            return self.sent[msg_type]

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.front, self.back], [], [], 0.1)
            for s in ready:
                try:
                    data, addr = s.recvfrom(65535)
                except OSError:
                    continue
                if s is self.front:
                    self._client = addr
                    self.back.send(data)
                    t = time.monotonic()
                    msgs = self._parser.parse_buffer(data) or []
                    with self._lock:
                        for m in msgs:
                            self.sent[m.get_type()] += 1
                            if m.get_type() == self.record:
                                self.times.append(t)
                elif self._client is not None:
                    self.front.sendto(data, self._client)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.front.close()
        self.back.close()


class Gcs:
    """A pymavlink ground station pumping in its own thread (heartbeats while ``heartbeats`` is set)."""

    def __init__(self, port: int, speedup: float) -> None:
        mavutil.set_dialect("ardupilotmega")
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=255, source_component=190
        )
        self.speedup = speedup
        self.heartbeats = threading.Event()
        self.heartbeats.set()
        self.last: dict[str, Any] = {}
        self.acks: list[Any] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gcs", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        next_hb = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_hb:
                next_hb = now + 1.0 / self.speedup
                if self.heartbeats.is_set():
                    self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            m = self.conn.recv_match(blocking=True, timeout=0.02)
            while m is not None:
                with self._lock:
                    self.last[m.get_type()] = m
                    if m.get_type() == "COMMAND_ACK":
                        self.acks.append(m)
                m = self.conn.recv_match(blocking=False)

    def msg(self, t: str) -> Any:
        with self._lock:
            return self.last.get(t)

    def command(self, command: int, *params: float, timeout_s: float = 10.0) -> int:
        p = list(params) + [0.0] * (7 - len(params))
        with self._lock:
            self.acks.clear()
        self.conn.mav.command_long_send(1, 1, command, 0, *p)

        def ack() -> Any:
            with self._lock:
                return next((a for a in self.acks if a.command == command), None)

        return wait_for(ack, timeout_s, f"ACK of {command}").result

    def set_mode(self, mode: int) -> int:
        return self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)

    def set_param(self, name: str, value: float) -> None:
        self.conn.mav.param_set_send(1, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32)

        def echoed() -> bool:
            m = self.msg("PARAM_VALUE")
            return m is not None and m.param_id == name and math.isclose(m.param_value, value)

        wait_for(echoed, 10, f"PARAM_VALUE {name}={value}")

    def mode(self) -> int | None:
        hb = self.msg("HEARTBEAT")
        return hb.custom_mode if hb is not None else None

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.conn.close()


def wait_for(pred: Callable[[], Any], timeout_s: float, what: str, poll_s: float = 0.005) -> Any:
    """Test ``pred`` until truthy or the wall deadline passes (then AssertionError naming ``what``)."""
    end = time.monotonic() + timeout_s
    while True:
        r = pred()
        if r:
            return r
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout_s:.1f} s waiting for {what}")
        time.sleep(poll_s)
