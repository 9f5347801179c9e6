"""Bench (a): command -> COMMAND_ACK latency of the model's MAVLink endpoint over loopback UDP.

Starts the model (``python -m autopilot_model.sitl``) in real time (speedup 1) and in lockstep as fast
as it goes (speedup 0), sends ``--count`` COMMAND_LONGs one after the other from pymavlink and times
each until its ACK (wall clock). Prints p50 / p99 / max per mode. In real time the main loop runs at
500 Hz, so the ACK waits for the next poll: the floor is the time left in the current 2 ms period.
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from harness import ROOT
from taskflight_common.ports import free_ports


def measure(speedup: float, count: int) -> list[float]:
    port = free_ports(1, socket.SOCK_DGRAM)[0]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-m", "autopilot_model.sitl",
                             "--mavlink", f"udpin:127.0.0.1:{port}",
                             "--speedup", str(speedup), "--state-dir", tempfile.mkdtemp(prefix="tf_lat_"),
                             "--no-persist"], cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        while not proc.stdout.readline().startswith("READY"):
            pass
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.settimeout(2.0)
        mav = mavlink2.MAVLink(None, 255, 190)
        rx = mavlink2.MAVLink(None, 0, 0)
        rx.robust_parsing = True
        addr = ("127.0.0.1", port)
        sock.sendto(mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav), addr)
        # quiet the telemetry so the ACK is not queued behind it
        sock.sendto(mav.request_data_stream_encode(1, 1, 0, 0, 0).pack(mav), addr)
        out: list[float] = []
        for i in range(count):
            msg = mav.command_long_encode(1, 1, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                          mavlink2.MAVLINK_MSG_ID_SYSTEM_TIME, -1, 0, 0, 0, 0, 0)
            data = msg.pack(mav)
            mav.seq = (mav.seq + 1) & 0xFF
            t0 = time.perf_counter()
            sock.sendto(data, addr)
            got = False
            while not got:
                for m in rx.parse_buffer(sock.recv(4096)) or []:
                    if m.get_type() == "COMMAND_ACK" and m.command == mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL:
                        got = True
            if i >= 10:  # warm-up
                out.append(time.perf_counter() - t0)
        return out
    finally:
        proc.terminate()
        proc.wait(10)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=1000)
    args = p.parse_args()
    print(f"{'mode':28s} {'n':>6s} {'p50 ms':>8s} {'p99 ms':>8s} {'max ms':>8s}")
    for label, speedup in (("real time (500 Hz, 1x)", 1.0), ("lockstep, as fast as it goes", 0.0)):
        lat = sorted(measure(speedup, args.count))
        p50 = statistics.median(lat) * 1e3
        p99 = lat[int(0.99 * (len(lat) - 1))] * 1e3
        print(f"{label:28s} {len(lat):6d} {p50:8.3f} {p99:8.3f} {lat[-1] * 1e3:8.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
