"""Bench (b): messages per second the endpoint handles under a flood, while the 500 Hz loop keeps its rate.

The model runs in this process in real time (speedup 1, 500 Hz). A second process floods its UDP
endpoint as fast as it can with what a companion sends (SET_POSITION_TARGET_LOCAL_NED, HEARTBEAT,
and a COMMAND_LONG now and then). Reported: messages handled per second (the endpoint's ``rx``
counter), datagrams sent and dropped by the kernel, the loop's achieved rate (simulated seconds per
wall second; 1.0 = kept its rate) and its overruns. The per-poll read budget (POLL_BUDGET_S) is what
keeps the loop on time: beyond it, datagrams wait in the socket buffer (and the kernel drops the
excess), the loop does not stretch.
"""

from __future__ import annotations

import argparse
import logging
import multiprocessing as mp
import socket
import sys
import tempfile
import time

from taskflight_common.ports import free_ports


def flooder(port: int, stop_at: float, counter: mp.Value) -> None:  # type: ignore[type-arg]
    from pymavlink.dialects.v20 import ardupilotmega as m2

    mav = m2.MAVLink(None, 255, 190)
    frames = []
    for i in range(64):
        if i % 16 == 0:
            msg = mav.command_long_encode(1, 1, m2.MAV_CMD_REQUEST_MESSAGE, 0, 2, 0, 0, 0, 0, 0, 0)
        elif i % 8 == 0:
            msg = mav.heartbeat_encode(6, 8, 0, 0, 0)
        else:
            msg = mav.set_position_target_local_ned_encode(0, 1, 1, 1, 0b110111000111, 0, 0, 0, 1.0, 0, 0,
                                                            0, 0, 0, 0, 0)
        frames.append(msg.pack(mav))
        mav.seq = (mav.seq + 1) & 0xFF
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    addr = ("127.0.0.1", port)
    n = 0
    while time.time() < stop_at:
        for f in frames:
            s.sendto(f, addr)
        n += len(frames)
    counter.value = n


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0, help="flood duration (wall = simulated)")
    args = p.parse_args()
    logging.basicConfig(level=logging.WARNING)
    from autopilot_model.sitl import Sitl

    port = free_ports(1, socket.SOCK_DGRAM)[0]
    sitl = Sitl(urls=[f"udpin:127.0.0.1:{port}"], state_dir=tempfile.mkdtemp(prefix="tf_flood_"),
                speedup=1.0, persist=False)
    v = sitl.vehicle
    v.clock.set_speedup(0)
    v.run_until(lambda: v.estimator.healthy, 60)
    # baseline: one quiet second in real time
    v.clock.set_speedup(1.0)
    results = []
    for label, flood in (("idle", False), ("flood", True)):
        counter = mp.Value("q", 0)
        proc = None
        if flood:
            proc = mp.Process(target=flooder, args=(port, time.time() + args.seconds + 0.5, counter))
            proc.start()
            time.sleep(0.2)
        rx0 = sitl.endpoint.stats["rx"]
        v.loop.stats.reset()
        v.clock.set_speedup(1.0)
        sim0, w0 = v.clock.now(), time.perf_counter()
        v.run_for(args.seconds)
        wall = time.perf_counter() - w0
        sim = v.clock.now() - sim0
        rx = sitl.endpoint.stats["rx"] - rx0
        if proc is not None:
            proc.join()
        results.append((label, rx / wall, counter.value / wall if flood else 0.0, sim / wall,
                        v.loop.stats.overruns, v.loop.stats.iterations()))
    sitl.close()
    print(f"{'load':8s} {'handled msg/s':>14s} {'sent msg/s':>12s} {'sim s / wall s':>15s} "
          f"{'overruns':>9s} {'iterations':>11s}")
    for label, handled, sent, ratio, overruns, iters in results:
        print(f"{label:8s} {handled:14,.0f} {sent:12,.0f} {ratio:15.3f} {overruns:9d} {iters:11d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
