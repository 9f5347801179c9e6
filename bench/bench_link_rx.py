"""Bench: what the companion's MAVLink link receives from the model, and what each message costs it.

Two measurements, a table each:

1. **Stream**: the model (:class:`harness.model.SitlProcess`, real time) and one companion
   :class:`~companion.link.connection.MavlinkLink` on ``udpout:``, which asks for its stream plan; over
   ``--window`` wall seconds, messages and datagrams a second (the model gathers what one telemetry call
   sends to a link into one datagram, as ArduPilot's serial drivers write their buffer).
2. **Receive cost**: ``--count`` messages (ATTITUDE and LOCAL_POSITION_NED in turn) sent over loopback to a
   ``MavlinkLink``, 1, 2 and 4 to a datagram, paced; the CPU time of its receive thread per message
   (``pthread_getcpuclockid``), median of ``--repeat`` runs.
"""

from __future__ import annotations

import argparse
import socket
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from bench.common import machine, table
from companion.link.connection import M, MavlinkLink
from harness.model import SitlProcess
from harness.timing import wait_for
from taskflight_common.ports import free_ports


def _rx_cpu_s() -> float:
    th = next(t for t in threading.enumerate() if t.name == "mavlink-rx")
    assert th.ident is not None
    return time.clock_gettime(time.pthread_getcpuclockid(th.ident))


def stream(window_s: float) -> tuple[float, float, str]:
    """(messages/s, datagrams/s, stream mode) the model sends one companion link."""
    port = free_ports(1, socket.SOCK_DGRAM)[0]
    model = SitlProcess([f"udpin:127.0.0.1:{port}"], Path(tempfile.mkdtemp(prefix="tf_rx_")), speedup=1.0,
                        extra=["--no-persist"])  # started: READY
    link = MavlinkLink(f"udpout:127.0.0.1:{port}")
    datagrams = [0]
    try:
        link.start()
        recv = link._conn.recv

        def counted(*a: Any) -> Any:
            data = recv(*a)
            if data:
                datagrams[0] += 1
            return data
        link._conn.recv = counted

        def pump() -> bool:
            link.periodic(link.clock.now())
            return link.streams_mode != "none" and link.mirror.snapshot().home is not None
        wait_for(pump, 30, "the streams asked for", poll_s=0.05)
        end = time.monotonic() + 3.0  # every stream at its rate
        wait_for(lambda: pump() and time.monotonic() > end, 10, "3 s of streams", poll_s=0.05)
        m0, d0, t0 = link.stats["rx"], datagrams[0], time.monotonic()
        end = t0 + window_s
        wait_for(lambda: pump() and time.monotonic() > end, window_s + 10, "the window", poll_s=0.05)
        dt = time.monotonic() - t0
        return (link.stats["rx"] - m0) / dt, (datagrams[0] - d0) / dt, link.streams_mode
    finally:
        link.close()
        model.stop()


def receive_cost(per_datagram: int, count: int) -> float:
    """CPU seconds of the receive thread per message, ``per_datagram`` messages to a datagram."""
    ap = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ap.bind(("127.0.0.1", 0))
    ap.settimeout(5.0)
    link = MavlinkLink(f"udpout:127.0.0.1:{ap.getsockname()[1]}")
    link.start()
    try:
        link.periodic(link.clock.now())
        to = ap.recvfrom(2048)[1]  # the link's heartbeat: where it listens
        mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
        hb = mav.heartbeat_encode(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 1, 4, 3, 3)
        ap.sendto(hb.pack(mav), to)
        wait_for(lambda: link.target_system == 1, 5, "the heartbeat taken")
        msgs = [mav.local_position_ned_encode(1000 + i, 1.0, 2.0, -3.0, 0, 0, 0).pack(mav) if i % 2 else
                mav.attitude_encode(1000 + i, 0.1, 0.2, 0.3, 0, 0, 0).pack(mav) for i in range(count)]
        rx0, c0 = link.stats["rx"], _rx_cpu_s()
        for i in range(0, count, per_datagram):
            ap.sendto(b"".join(msgs[i:i + per_datagram]), to)
            time.sleep(0.0004 * per_datagram)  # ~2,500 messages a second: no queue builds up
        wait_for(lambda: link.stats["rx"] - rx0 >= count, 30, f"{count} messages received")
        return (_rx_cpu_s() - c0) / count
    finally:
        link.close()
        ap.close()


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--window", type=float, default=10.0, help="wall seconds the stream is counted")
    p.add_argument("--count", type=int, default=6000, help="messages per receive-cost run")
    p.add_argument("--repeat", type=int, default=3, help="receive-cost runs per row (median)")
    args = p.parse_args()
    print(f"companion MAVLink link: {machine()}", file=sys.stderr)
    msgs, dgrams, mode = stream(args.window)
    print(table(["what", "messages/s", "datagrams/s", "messages per datagram", "streams"],
                [["model -> one companion link, idle on the ground", f"{msgs:.1f}", f"{dgrams:.1f}",
                  f"{msgs / dgrams:.2f}" if dgrams else "-", mode]]))
    print()
    rows = []
    for k in (1, 2, 4):
        runs = [receive_cost(k, args.count) for _ in range(args.repeat)]
        rows.append([k, args.count, f"{statistics.median(runs) * 1e6:.1f}",
                     " / ".join(f"{r * 1e6:.1f}" for r in runs)])
    print(table(["messages per datagram", "messages", "receive thread CPU us per message (median)", "runs"],
                rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
