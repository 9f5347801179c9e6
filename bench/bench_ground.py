"""The ground service under a fleet of 100: REST latency, WebSocket snapshot latency, CPU.

``taskflight ground`` runs as its own process on a real multicast team link; this script feeds that link
with N members' rows at 10 Hz (the team wire format of seed 003 Sec. III-A, each member's own row as it
would flood it, moving on a circle), then measures

* REST latency (p50 / p99) of ``GET /api/vehicles`` (N records with health), ``GET /api/tasks``,
  ``POST /api/tasks`` + ``DELETE /api/tasks/{id}`` (a write: the ledger saved to SQLite, the board
  published), sequential requests from one client;
* WebSocket snapshot latency: each row carries its send time (in its altitude, 1 cm = 10 ms of
  resolution); latency = the snapshot's arrival - the newest send time it shows (the feed -> team link ->
  station -> snapshot -> socket path; includes the wait for the next snapshot period);
* the service's CPU share (% of one core, /proc) over the window.

Run: ``python bench/bench_ground.py [--vehicles 100] [--seconds 20]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

from bench.common import machine, pct, table
from companion.team.transport import open_transport
from companion.team.types import MemberEntry, MemberStatus
from companion.team.wire import encode_packets
from harness.ground import OBSERVER, GroundProcess
from harness.team import new_team_url

HOME = (-35.363261, 149.165230)
WRAP_S = 300.0  # send times ride in the altitude modulo this (cm16 carries up to 327 m)


def cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def feed(url: str, n: int, rate_hz: float, stop: threading.Event) -> None:
    """N members' rows at ``rate_hz`` each on the team link."""
    tr = open_transport(url, member=1)
    seq = 0
    period = 1.0 / rate_hz
    next_t = time.monotonic()
    while not stop.is_set():
        seq += 1
        now = time.time()
        for m in range(1, n + 1):
            a = 2 * math.pi * (m / n) + 0.05 * now
            lat = HOME[0] + 0.001 * math.sin(a)
            lon = HOME[1] + 0.001 * math.cos(a)
            row = MemberEntry(member=m, stamp=now, seq=seq, position=(lat, lon, round(now % WRAP_S, 2)),
                              velocity=(1.0, 0.5, 0.0), status=MemberStatus.IDLE, name=f"sim{m}")
            for pkt in encode_packets(m, [row]):
                tr.send(pkt)
        next_t += period
        stop.wait(max(0.0, next_t - time.monotonic()))
    tr.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, default=100)
    ap.add_argument("--rate", type=float, default=10.0, help="rows per member per second")
    ap.add_argument("--seconds", type=float, default=20.0, help="measurement window")
    args = ap.parse_args()
    team = new_team_url()
    ground = GroundProcess(Path(tempfile.mkdtemp(prefix="bench_ground")), team, {}).start()
    assert ground.proc is not None
    pid = ground.proc.pid
    http = ground.http(timeout=10)
    stop = threading.Event()
    feeder = threading.Thread(target=feed, args=(team, args.vehicles, args.rate, stop), daemon=True)
    try:
        feeder.start()
        deadline = time.monotonic() + 30
        while len(http.get("/api/vehicles").json()["vehicles"]) < args.vehicles:
            if time.monotonic() > deadline:
                raise SystemExit("not every member heard")
            time.sleep(0.2)
        lat_ws: list[float] = []
        snaps = [0]
        ws_stop = threading.Event()

        def watch() -> None:
            with ground.ws(OBSERVER) as ws:
                while not ws_stop.is_set():
                    m = json.loads(ws.recv(timeout=5))
                    if m["type"] != "snapshot":
                        continue
                    now = time.time()
                    sent = [v["position"]["alt"] for v in m["vehicles"] if v["position"]]
                    if len(sent) < args.vehicles:
                        continue
                    newest = max(sent)
                    lat_ws.append(((now % WRAP_S) - newest) % WRAP_S)
                    snaps[0] += 1

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        c0, t0 = cpu_s(pid), time.monotonic()
        lat: dict[str, list[float]] = {"GET /api/vehicles": [], "GET /api/tasks": [],
                                       "POST+DELETE /api/tasks": []}
        end = t0 + args.seconds
        k = 0
        while time.monotonic() < end:
            k += 1
            a = time.perf_counter()
            r = http.get("/api/vehicles")
            lat["GET /api/vehicles"].append(time.perf_counter() - a)
            assert r.status_code == 200 and len(r.json()["vehicles"]) >= args.vehicles
            a = time.perf_counter()
            http.get("/api/tasks")
            lat["GET /api/tasks"].append(time.perf_counter() - a)
            if k % 5 == 0:
                a = time.perf_counter()
                r = http.post("/api/tasks", json={"type": "visit", "point": [HOME[0] + 0.0002, HOME[1], 10]})
                http.delete(f"/api/tasks/{r.json()['ids'][0]}")
                lat["POST+DELETE /api/tasks"].append(time.perf_counter() - a)
            time.sleep(0.02)
        wall = time.monotonic() - t0
        cpu = 100.0 * (cpu_s(pid) - c0) / wall
        ws_stop.set()
        watcher.join(6)
        print(f"# bench_ground: {args.vehicles} members at {args.rate:g} Hz on the team link, {wall:.0f} s")
        print(f"# {machine()}")
        rows = [[name, len(v), f"{1e3 * pct(v, 0.5):.1f}", f"{1e3 * pct(v, 0.99):.1f}", "<= 50"]
                for name, v in lat.items()]
        rows.append(["WebSocket snapshot (feed -> socket)", len(lat_ws), f"{1e3 * pct(lat_ws, 0.5):.1f}",
                     f"{1e3 * pct(lat_ws, 0.95):.1f} (p95)", "<= 250 (p95)"])
        print(table(["measure", "n", "p50 ms", "p99 ms", "target ms"], rows))
        print()
        print(table(["service CPU (% of one core)", "snapshots/s"],
                    [[f"{cpu:.1f}", f"{snaps[0] / wall:.1f}"]]))
    finally:
        stop.set()
        http.close()
        ground.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
