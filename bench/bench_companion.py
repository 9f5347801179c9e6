"""Bench: the companion's setpoint stream against each autopilot over loopback UDP.

Starts the autopilot (the bundled model, ``python -m autopilot_model.sitl``, or ArduPilot's copter SITL
named by ``TASKFLIGHT_ARDUCOPTER``; both paced at ``--speedup``) behind a UDP wire tap and a
:class:`~companion.node.QuadNode`, then measures

* the streamed setpoint rate and interval jitter (p50 / p99 of |interval - period|) at 20 and 50 Hz,
  from the tap's arrival times converted to autopilot time (wall x the autopilot clock's measured rate);
* the latency from user_confirm to the first setpoint of the next command (autopilot time);
* the tracking figure of :mod:`companion.tracking` on a three-waypoint flight: each streamed setpoint
  against LOCAL_POSITION_NED interpolated to its autopilot time (horizontal and vertical RMS and max).
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.common import add_autopilot_argument, chosen_autopilots, machine, pct, table
from companion.builder import CompanionConfig, build_companion
from companion.flight import command_from_dict as cmd
from companion.node import QuadNode
from companion.tracking import StreamRecorder
from harness.autopilot import start_autopilot
from harness.timing import wait_for


def sim_wait(node: QuadNode, seconds: float, speedup: float) -> None:
    t = node.clock.now() + seconds
    wait_for(lambda: node.clock.now() >= t, 10 + 3 * seconds / speedup, f"{seconds} s of autopilot time")


def fly(kind: str, rate: float, speedup: float, state: Path, sample_s: float) -> dict[str, Any]:
    ap = start_autopilot(kind, state, speedup, record="SET_POSITION_TARGET_LOCAL_NED")
    tap = ap.tap
    companion = build_companion(CompanionConfig(ap.companion_url, rate_hz=rate, behaviors=False,
                                                control_port=None))
    node = companion.node
    streamed: list[tuple[float, Any]] = []  # (autopilot time, setpoint)
    node.setpoint_listeners.append(lambda sp, f, t: streamed.append((t, sp)))
    out: dict[str, Any] = {}
    try:
        companion.start()
        w = 30 + 3 * 60 / speedup
        wait_for(lambda: node.link.mirror.snapshot().position is not None, w, "telemetry")
        node.add_command(
            cmd({"vertical": {"mode": "POS", "altitude": 5, "take_off": True}, "end": {"e_v": True}})
        )
        node.run()
        wait_for(lambda: node.queue.status().current_command_index >= 1, w, "take-off")
        # rate and jitter while hovering
        n0 = len(tap.times)
        sim_wait(node, sample_s, speedup)
        times = tap.times[n0:]
        scale = node.clock.rate  # autopilot seconds per wall second, as the companion measures it
        iv = [(b - a) * scale for a, b in itertools.pairwise(times)]
        out["rate"] = (len(times) - 1) / ((times[-1] - times[0]) * scale)
        out["jitter"] = [abs(x - 1 / rate) * 1000 for x in iv]
        # user_confirm -> first setpoint of the next command
        lat = []
        for _ in range(8):
            confirm_id, next_id = node.add_commands([cmd({"end": {"e_user": True}}),
                                                     cmd({"end": {"e_wait": 0.2}})])
            wait_for(
                lambda i=confirm_id: (
                    node.queue.status().confirmation_required_status
                    and node.queue.status().current_command_id == i
                ),
                w,
                "waiting for confirmation",
            )
            t0 = node.clock.now()
            node.user_confirm()
            first = wait_for(
                lambda i=next_id: next((t for t, sp in reversed(streamed) if sp.command_id == i), None),
                w,
                "next command streamed",
            )
            lat.append((first - t0) * 1000)
            node.queue.events.wait_for(next_id, timeout_s=w)
        out["latency"] = lat
        # tracking on the waypoint flight (the figure of the demo's report, companion.tracking)
        recorder = StreamRecorder(node)
        for n, e, alt in ((15.0, 0.0, 6.0), (15.0, 15.0, 8.0), (0.0, 0.0, 5.0)):
            node.add_command(
                cmd(
                    {
                        "horizontal": {"mode": "POS", "north": n, "east": e},
                        "vertical": {"mode": "WITH_HOR", "altitude": alt},
                        "end": {"e_h": True, "e_v": True},
                    }
                )
            )
        end = len(node.queue.commands)
        wait_for(lambda: node.queue.status().current_command_index >= end, w + 60 / speedup * 3, "waypoints")
        sim_wait(node, 2.0, speedup)
        out["track"] = recorder.tracking()
    finally:
        companion.close()
        ap.close()
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--speedup", type=float, default=2.0, help="model speedup (1 = real time)")
    p.add_argument("--sample", type=float, default=10.0, help="seconds of autopilot time per rate sample")
    add_autopilot_argument(p)
    args = p.parse_args()
    kinds = chosen_autopilots(p, args)
    rows_rate, rows_other = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for kind, rate in itertools.product(kinds, (20.0, 50.0)):
            r = fly(kind, rate, args.speedup, Path(tmp) / f"{kind}{rate:g}", args.sample)
            rows_rate.append(
                (kind, f"{rate:g}", r["rate"], pct(r["jitter"], 0.5), pct(r["jitter"], 0.99),
                 max(r["jitter"]))
            )
            tr = r["track"]
            rows_other.append((kind, f"{rate:g}", statistics.median(r["latency"]), max(r["latency"]),
                               tr.h_rms, tr.h_max, tr.v_rms, tr.v_max, tr.compared))
    print(f"# bench_companion ({machine()}), autopilot speedup {args.speedup:g}; times are autopilot time\n")
    print(table(["autopilot", "stream Hz", "measured Hz", "jitter p50 ms", "jitter p99 ms", "jitter max ms"],
                rows_rate))
    print()
    print(
        table(
            [
                "autopilot",
                "stream Hz",
                "confirm->next p50 ms",
                "confirm->next max ms",
                "horizontal RMS m",
                "horizontal max m",
                "vertical RMS m",
                "vertical max m",
                "setpoints",
            ],
            rows_other,
        )
    )
    return 0


if __name__ == "__main__":
    start = time.monotonic()
    code = main()
    print(f"\n(wall {time.monotonic() - start:.0f} s)")
    sys.exit(code)
