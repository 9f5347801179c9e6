"""Helpers for the companion's integration tests and bench (no tests here); the SITL process, the
ground station and ``wait_for`` are in :mod:`mavlink_support`.

* :class:`WireTap`: a UDP relay between the companion and the model that decodes what the companion
  sends, so tests count SET_POSITION_TARGET_LOCAL_NED *on the wire*;
* :func:`cmd`: a flight command from plain data (the codec form the HTTP surface takes).
"""

from __future__ import annotations

import select
import socket
import threading
import time
from collections import Counter
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from companion.flight import FlightCommand, command_from_dict


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

