"""Bench: the behavior coordinator's coordination time (seed 001 Sec. 7.1.2) in a scripted mission.

Starts the autopilot (the bundled model, or ArduPilot's copter SITL named by ``TASKFLIGHT_ARDUCOPTER``)
behind the UDP wire tap, a :class:`~companion.node.QuadNode` with its executive layer and HTTP control
surface, and flies a scripted mission by activation requests over HTTP (the mission requester):
TAKE_OFF, then rounds of GO_TO_POINT, ROTATE and FOLLOW_PATH around a square, each waited for to
its end, until at least ``--activations`` requests were accepted. Measured:

* the coordination time tau_i of Sec. 7.1.2: from the coordinator receiving the request to it asking
  the behavior's execution controller to start (wall clock, ``time.perf_counter``); mean, min, max
  (seed 001 measured 119 / 36 / 204 ms on ROS);
* request -> first setpoint of the new behavior on the wire: from just before the HTTP request to the
  first SET_POSITION_TARGET_LOCAL_NED the link sends for one of the behavior's commands, in
  autopilot time (the stream ticks at 20 Hz, so up to one period plus the HTTP round trip; not for
  TAKE_OFF, whose stream starts once the autopilot has armed and lifted off);
* how each behavior ended (all must be goal_achieved).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import httpx

from bench.common import add_autopilot_argument, chosen_autopilots, machine, pct, table
from companion.builder import CompanionConfig, build_companion
from harness.autopilot import start_autopilot
from harness.timing import wait_for


def mission() -> list[str]:
    """One round of the scripted mission (a 6 m square at 5 m, turning at each corner)."""
    corners = [(6, 0), (6, 6), (0, 6), (0, 0)]
    steps = []
    for i, (n, e) in enumerate(corners):
        steps.append(f"GO_TO_POINT coordinate: ({n}, {e}, 5)")
        steps.append(f"ROTATE angle: {90 * (i + 1) % 360}")
    steps.append("FOLLOW_PATH path: ((3, 0, 6), (3, 3, 6), (0, 0, 5))")
    return steps


def fly(kind: str, speedup: float, state: Path, wanted: int) -> dict[str, Any]:
    state.mkdir(parents=True, exist_ok=True)
    ap = start_autopilot(kind, state, speedup)
    companion = build_companion(CompanionConfig(ap.companion_url, rate_hz=20.0, missions=False,
                                                control_port=0, behavior_log=state / "behaviors.jsonl"))
    node, layer = companion.node, companion.layer
    assert layer is not None
    first_seen: dict[int, float] = {}  # command id -> autopilot time of its first streamed setpoint
    lock = threading.Lock()

    def on_setpoint(sp: Any, fields: Any, t: float) -> None:
        if sp.command_id is not None and sp.command_id not in first_seen:
            with lock:
                first_seen.setdefault(sp.command_id, t)

    node.setpoint_listeners.append(on_setpoint)
    out: dict[str, Any] = {"wire_ms": [], "causes": Counter()}
    try:
        companion.start()
        assert companion.server is not None
        http = httpx.Client(base_url=companion.server.url, timeout=10.0)
        w = 30 + 3 * 60 / speedup
        wait_for(lambda: layer.coordinator.is_active("SELF_LOCALIZE"), w, "a healthy estimate")

        def run(text: str) -> None:
            t0 = node.clock.now()
            r = http.post("/behaviors/activate", json={"text": text, "requester": "mission"}).json()
            if not r["accepted"]:
                raise RuntimeError(f"{text}: {r['reason']}")
            ctrl = layer.coordinator.controllers[r["behavior"]]
            ids = list(getattr(ctrl, "command_ids", []))
            if ids and r["behavior"] != "TAKE_OFF":  # a take-off streams once the autopilot lifted off
                t1 = wait_for(lambda: first_seen.get(ids[0]), w, f"first setpoint of {text}")
                out["wire_ms"].append((t1 - t0) * 1000)
            aid = r["activation_id"]
            end = wait_for(lambda: next((e for e in layer.coordinator.ended if e.activation_id == aid), None),
                           w, f"end of {text}")
            out["causes"][end.cause.value] += 1

        run("TAKE_OFF altitude: 5")
        wait_for(lambda: layer.coordinator.is_active("KEEP_HOVERING"), w, "hovering")
        rounds = 0
        while len(layer.coordinator.coordination_times) < wanted:
            for text in mission():
                run(text)
            rounds += 1
            print(f"  {kind}: round {rounds}, {len(layer.coordinator.coordination_times)} activations",
                  file=sys.stderr)
        out["tau_ms"] = [t * 1000 for t in layer.coordinator.coordination_times]
        http.close()
    finally:
        companion.close()
        ap.close()
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--speedup", type=float, default=4.0, help="autopilot speed-up (1 = real time)")
    p.add_argument("--activations", type=int, default=126, help="at least this many accepted activations")
    add_autopilot_argument(p)
    args = p.parse_args()
    kinds = chosen_autopilots(p, args)
    rows_tau, rows_wire = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in kinds:
            r = fly(kind, args.speedup, Path(tmp) / kind, args.activations)
            tau = r["tau_ms"]
            rows_tau.append((kind, len(tau), statistics.mean(tau), min(tau), max(tau), pct(tau, 0.99),
                             ", ".join(f"{k} {v}" for k, v in sorted(r["causes"].items()))))
            wire = r["wire_ms"]
            rows_wire.append((kind, len(wire), pct(wire, 0.5), pct(wire, 0.99), max(wire)))
    print(f"# bench_behaviors ({machine()}), autopilot speedup {args.speedup:g}\n")
    print(table(["autopilot", "activations", "tau mean ms", "tau min ms", "tau max ms", "tau p99 ms",
                 "terminations"], rows_tau))
    print()
    print(table(["autopilot", "behaviors", "request->wire p50 ms", "request->wire p99 ms",
                 "request->wire max ms"], rows_wire))
    print("\n(tau: wall clock; request->wire: autopilot time, the stream ticks every 50 ms)")
    return 0


if __name__ == "__main__":
    start = time.monotonic()
    code = main()
    print(f"\n(wall {time.monotonic() - start:.0f} s)")
    sys.exit(code)
