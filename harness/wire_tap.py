"""The wire tap: :class:`WireTap`, a UDP relay between the companion and the autopilot that decodes
what the companion sends, so tests count SET_POSITION_TARGET_LOCAL_NED *on the wire*; and
:func:`wire_violations`, the setpoints on the wire that break the limits."""

from __future__ import annotations

import math
import select
import socket
import threading
import time
from collections import Counter
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2


def _bound_socket(avoid: set[int]) -> socket.socket:
    """A UDP socket bound on loopback to a free port not in ``avoid``."""
    while True:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        if sock.getsockname()[1] not in avoid:
            return sock
        sock.close()


class WireTap:
    """A UDP relay that decodes what the companion sends.

    Whoever sends to ``127.0.0.1:port`` first (the *front*) is relayed to ``back_port`` and back.
    ``companion_side="front"``: the companion sends to the tap, the autopilot listens on ``back_port``
    (the model's udpin). ``"back"``: the autopilot sends to the tap (ArduCopter SITL's udpclient) and
    the companion listens on ``back_port``. Counts the message types the companion sends; keeps the
    decoded messages of the types in ``keep`` with their wall arrival time.
    """

    def __init__(self, back_port: int, record: str | None = None, companion_side: str = "front",
                 keep: tuple[str, ...] = ("SET_POSITION_TARGET_LOCAL_NED",), avoid: tuple[int, ...] = ()
                 ) -> None:
        if companion_side not in ("front", "back"):
            raise ValueError("companion_side: front or back")
        # neither of our own sockets may take a port chosen for someone else (a port freed a moment ago
        # is a likely next ephemeral port): a tap bound to the companion's port would talk to itself
        taken = {back_port, *avoid}
        self.front = _bound_socket(taken)
        self.port = self.front.getsockname()[1]
        self.back = _bound_socket(taken | {self.port})
        self.back.connect(("127.0.0.1", back_port))
        # non-blocking: select() may report a socket readable for an ICMP error that a send() then
        # consumes; a blocking recvfrom() would then wait for ever and stall the relay
        self.front.setblocking(False)
        self.back.setblocking(False)
        self.companion_side = companion_side
        self.sent: Counter[str] = Counter()
        #: wall arrival times of each message of type ``record`` (for the bench's jitter)
        self.record = record
        self.times: list[float] = []
        self.keep = frozenset(keep)
        #: (wall time, decoded message) of each kept message the companion sent
        self.messages: list[tuple[float, Any]] = []
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

    def kept(self, msg_type: str = "SET_POSITION_TARGET_LOCAL_NED") -> list[Any]:
        with self._lock:
            return [m for _, m in self.messages if m.get_type() == msg_type]

    def _parse(self, data: bytes) -> None:
        t = time.monotonic()
        msgs = self._parser.parse_buffer(data) or []
        with self._lock:
            for m in msgs:
                kind = m.get_type()
                self.sent[kind] += 1
                if kind == self.record:
                    self.times.append(t)
                if kind in self.keep:
                    self.messages.append((t, m))

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.front, self.back], [], [], 0.1)
            for s in ready:
                try:
                    data, addr = s.recvfrom(65535)
                except OSError:  # nothing after all (BlockingIOError), or an ICMP error
                    continue
                if s is self.front:
                    self._client = addr
                    try:
                        self.back.send(data)
                    except OSError:  # nobody listens there yet (ICMP port unreachable)
                        continue
                    if self.companion_side == "front":
                        self._parse(data)
                elif self._client is not None:
                    try:
                        self.front.sendto(data, self._client)
                    except OSError:
                        continue
                    if self.companion_side == "back":
                        self._parse(data)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.front.close()
        self.back.close()



def wire_violations(msgs: list[Any], limits: Any, rel_tol: float = 0.05, abs_tol: float = 2e-3
                    ) -> list[str]:
    """Continuity of decoded SET_POSITION_TARGET_LOCAL_NED messages (seed 000 Fig. 9, on the wire).

    Between consecutive messages (dt from their ``time_boot_ms``) the velocity may change by at most
    a_max * dt and, when both carry a position, the position by at most v_max * dt (horizontal norm
    and vertical); yaw by at most the yaw rate when both carry one. ``rel_tol`` / ``abs_tol`` absorb
    the millisecond stamps and float32 fields."""
    ignore_pos, ignore_yaw = 0b111, 1 << 10
    out: list[str] = []
    for i in range(1, len(msgs)):
        a, b = msgs[i - 1], msgs[i]
        dt = (b.time_boot_ms - a.time_boot_ms) / 1000.0
        if dt <= 0:
            continue
        checks = [("dv_h", math.hypot(b.vx - a.vx, b.vy - a.vy), limits.horizontal_acceleration * dt),
                  ("dv_v", abs(b.vz - a.vz), limits.vertical_acceleration * dt)]
        if not (a.type_mask | b.type_mask) & ignore_pos:
            checks += [("dp_h", math.hypot(b.x - a.x, b.y - a.y), limits.horizontal_speed * dt),
                       ("dp_v", abs(b.z - a.z), limits.vertical_speed * dt)]
        if not (a.type_mask | b.type_mask) & ignore_yaw:
            dyaw = abs(math.remainder(b.yaw - a.yaw, 2 * math.pi))
            checks.append(("dyaw", dyaw, math.radians(limits.yaw_rate) * dt))
        for name, value, bound in checks:
            if value > bound * (1 + rel_tol) + abs_tol:
                out.append(f"#{i} t={b.time_boot_ms} ms {name} {value:.4f} > {bound:.4f}")
    return out
