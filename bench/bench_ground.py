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

``--companions F`` registers every member with a companion control URL, as ``taskflight up`` does:
a fraction F of them answer (a companion-like HTTP endpoint per vehicle, each on its own port, served by
one asyncio process: ``GET /status``, ``/mission``, ``/beliefs`` with a realistic status, ``POST`` verbs
with ``{"ok": true}``; a collaborator, not under test), the others are *blackholes* (a port that
accepts connections and never answers: each poll of them runs into its time-out). Then also

* the WebSocket update interval (p95 of the time between two snapshots at the client);
* a command to a reachable vehicle (``POST /api/vehicles/{vid}/pause``: the service -> companion round
  trip) while the unreachable ones are polled.

``--bus zenoh`` runs the team on the Zenoh fleet bus instead (a ``taskflight router`` on loopback, the
service a client of it, as on a field network): a publisher process sends the N members' rows on the bus
and runs N real :class:`~companion.team.presence.Presence` publishers (the companion's own code: status
and mission at 2 Hz, the control URL with them); a fraction F (``--companions``, default 0.75) point at
companion-like endpoints that answer, the rest stop publishing their presence after 3 s (a companion whose
control surface died; their team rows go on: the service marks them unreachable after its lost time and
polls nobody). The command latency is then the
service -> companion round trip of a control URL learnt from the bus.

Run: ``python -m bench.bench_ground [--vehicles 100] [--seconds 20] [--companions 0.75] [--bus zenoh]``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from bench.common import machine, pct, table
from companion.team.transport import open_transport
from companion.team.types import MemberEntry, MemberStatus
from companion.team.wire import encode_packets
from harness.ground import OBSERVER, GroundProcess
from harness.team import new_team_url
from taskflight_common.ports import free_ports

HOME = (-35.363261, 149.165230)
WRAP_S = 300.0  # send times ride in the altitude modulo this (cm16 carries up to 327 m)


def cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def feed(url: str, n: int, rate_hz: float, stop: threading.Event) -> None:
    """N members' rows at ``rate_hz`` each on the team link."""
    tr = open_transport(url, member=None if url.startswith("zenoh:") else 1)
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


STATUS = {"queue": {"queue_status": "IDLE", "queue_system_status": "NORMAL",
                    "confirmation_required_status": False},
          "awaits_operator": False, "link": {"connected": True},
          "vehicle": {"mode": "GUIDED", "armed": True, "battery_remaining": 87.0, "battery_voltage": 12.4,
                      "attitude": [0.0, 0.0, 0.3], "velocity": [1.0, 0.5, 0.0], "gps_fix_type": 3,
                      "home": [HOME[0], HOME[1], 584.0], "global_position": [HOME[0], HOME[1], 590.0, 6.0]},
          "flight": {"phase": "hover"}, "team": {"member": 1}}
MISSION = {"state": "none", "active_node": None, "tree": None}


async def _serve(ports: list[int], blackholes: list[int]) -> None:
    """Companion-like endpoints on ``ports``; listening sockets never accepted on ``blackholes``."""
    status = json.dumps(STATUS).encode()
    bodies = {b"/status": status, b"/mission": json.dumps(MISSION).encode(),
              b"/beliefs": b'{"bindings": []}'}

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while True:
                head = await reader.readuntil(b"\r\n\r\n")
                line = head.split(b"\r\n", 1)[0].split()
                length = 0
                for h in head.split(b"\r\n")[1:]:
                    if h.lower().startswith(b"content-length:"):
                        length = int(h.split(b":", 1)[1])
                if length:
                    await reader.readexactly(length)
                path = line[1].split(b"?", 1)[0] if len(line) > 1 else b"/"
                body = bodies.get(path, b'{"ok": true}')
                writer.write(b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: "
                             + str(len(body)).encode() + b"\r\n\r\n" + body)
                await writer.drain()
        except (asyncio.IncompleteReadError, ConnectionError, asyncio.LimitOverrunError):
            writer.close()

    servers = [await asyncio.start_server(handle, "127.0.0.1", p) for p in ports]
    holes = []
    for p in blackholes:  # accept in the kernel (the backlog), never in the application: no answer ever
        s = socket.socket()
        s.bind(("127.0.0.1", p))
        s.listen(4096)
        holes.append(s)
    print("SERVING", flush=True)
    await asyncio.gather(*(srv.serve_forever() for srv in servers))


#: seconds a silent vehicle's presence is heard before it goes quiet (--bus zenoh)
SILENT_AFTER_S = 3.0


def _publish(url: str, n: int, rate_hz: float, urls: dict[int, str], silent: set[int]) -> None:
    """The ``--publish`` process: N members' rows and N Presence publishers on one bus session (each
    vehicle's ``status`` a companion's ``GET /status`` answer), until its stdin closes."""
    from companion.team.presence import Presence
    from companion.team.zenoh_transport import ZenohBus

    stop = threading.Event()
    feeder = threading.Thread(target=feed, args=(url, n, rate_hz, stop), daemon=True)
    feeder.start()
    bus = ZenohBus.open(url)

    def status_of(m: int) -> Any:
        def status() -> dict[str, Any]:
            st = json.loads(json.dumps(STATUS))
            st["team"]["member"] = m
            return st
        return status

    def url_of(m: int) -> Any:
        return lambda: urls.get(m)

    presences = {m: Presence(bus, m, name=f"sim{m}", status=status_of(m), mission=lambda: MISSION,
                             control_url=url_of(m), owns_bus=False).start()
                 for m in range(1, n + 1)}
    print("PUBLISHING", flush=True)
    time.sleep(SILENT_AFTER_S)
    for m in silent:
        presences[m].close()
    sys.stdin.read()  # until the bench closes it (or dies)
    stop.set()
    for p in presences.values():
        p.close()
    bus.close()


def _child(args: list[str], ready: str) -> subprocess.Popen[str]:
    """A helper process of the bench (its CPU is neither the bench's nor the service's), once it printed a
    line containing ``ready``."""
    proc = subprocess.Popen([sys.executable, *args], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            cwd=Path(__file__).resolve().parents[1])
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if ready not in line:
        proc.kill()
        raise SystemExit(f"bench helper {' '.join(args[:4])} did not start: {line!r}")
    return proc


def fake_companions(ports: list[int], blackholes: list[int]) -> subprocess.Popen[str]:
    """The companion-like endpoints in a process of their own."""
    return _child(["-m", "bench.bench_ground", "--serve", ",".join(map(str, ports)),
                   "--holes", ",".join(map(str, blackholes))], "SERVING")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, default=100)
    ap.add_argument("--rate", type=float, default=10.0, help="rows per member per second")
    ap.add_argument("--seconds", type=float, default=20.0, help="measurement window")
    ap.add_argument("--companions", type=float, default=None, metavar="F",
                    help="register every member's companion; the fraction F answers, the rest are blackholes")
    ap.add_argument("--bus", choices=("udp", "zenoh"), default="udp",
                    help="the team link: UDP multicast (the service polls the registered companions) or the "
                         "Zenoh fleet bus through a router (the companions publish; nobody is polled)")
    ap.add_argument("--publish", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--serve", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--holes", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.serve is not None:
        asyncio.run(_serve([int(p) for p in args.serve.split(",") if p],
                           [int(p) for p in args.holes.split(",") if p]))
        return 0
    if args.publish is not None:
        spec = json.loads(args.publish)
        _publish(spec["url"], args.vehicles, args.rate, {int(k): v for k, v in spec["urls"].items()},
                 set(spec["silent"]))
        return 0
    zenoh = args.bus == "zenoh"
    fraction = args.companions if args.companions is not None else (0.75 if zenoh else None)
    children: list[subprocess.Popen[str]] = []
    team = new_team_url()
    if zenoh:
        rport = free_ports(1, socket.SOCK_STREAM)[0]
        children.append(_child(["-m", "taskflight.cli", "router", "--listen", f"tcp/127.0.0.1:{rport}"],
                               "listening"))
        team = f"zenoh:tcp/127.0.0.1:{rport}?team=bench{os.getpid()}"
    companions: dict[int, str] = {}
    reachable: list[int] = []
    if fraction is not None:
        ports = free_ports(args.vehicles, socket.SOCK_STREAM)
        n_ok = round(fraction * args.vehicles)
        reachable = list(range(1, n_ok + 1))
        children.append(fake_companions(ports[:n_ok], ports[n_ok:]))
        companions = {m: f"http://127.0.0.1:{ports[m - 1]}" for m in range(1, args.vehicles + 1)}
    stop = threading.Event()
    if zenoh:  # the vehicles publish (rows and presence); the service is told no companion
        spec = {"url": team, "urls": companions, "silent": sorted(set(companions) - set(reachable))}
        children.append(_child(["-m", "bench.bench_ground", "--vehicles", str(args.vehicles), "--rate",
                                str(args.rate), "--publish", json.dumps(spec)], "PUBLISHING"))
        companions = {}
    ground = GroundProcess(Path(tempfile.mkdtemp(prefix="bench_ground")), team, companions).start()
    assert ground.proc is not None
    pid = ground.proc.pid
    http = ground.http(timeout=10)
    ophttp = ground.http(timeout=10)
    feeder = threading.Thread(target=feed, args=(team, args.vehicles, args.rate, stop), daemon=True)
    try:
        if not zenoh:
            feeder.start()
        deadline = time.monotonic() + 30
        while len(http.get("/api/vehicles").json()["vehicles"]) < args.vehicles:
            if time.monotonic() > deadline:
                raise SystemExit("not every member heard")
            time.sleep(0.2)
        if zenoh:  # the silent ones marked unreachable, the others' control URLs learnt from the bus
            deadline = time.monotonic() + 30
            while True:
                vs = http.get("/api/vehicles").json()["vehicles"]
                ok = sum(v["companion"] == "ok" for v in vs)
                lost = sum(v["companion"] == "unreachable" for v in vs)
                if ok == len(reachable) and lost == args.vehicles - len(reachable):
                    break
                if time.monotonic() > deadline:
                    raise SystemExit(f"bus: {ok} companions ok, {lost} unreachable, want {len(reachable)} "
                                     f"and {args.vehicles - len(reachable)}")
                time.sleep(0.5)
        lat_ws: list[float] = []
        intervals: list[float] = []
        snaps = [0]
        ws_stop = threading.Event()

        last = [0.0]

        def watch() -> None:
            with ground.ws(OBSERVER) as ws:
                while not ws_stop.is_set():
                    m = json.loads(ws.recv(timeout=5))
                    if m["type"] != "snapshot":
                        continue
                    now = time.time()
                    if snaps[0]:
                        intervals.append(now - last[0])
                    last[0] = now
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
        cmd: list[float] = []
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
            if reachable and k % 3 == 0:
                a = time.perf_counter()
                r = ophttp.post(f"/api/vehicles/{reachable[k % len(reachable)]}/pause")
                cmd.append(time.perf_counter() - a)
                assert r.status_code == 200, r.text
            time.sleep(0.02)
        wall = time.monotonic() - t0
        cpu = 100.0 * (cpu_s(pid) - c0) / wall
        ws_stop.set()
        watcher.join(6)
        if zenoh:
            extra = (f"; Zenoh fleet bus through a router: {args.vehicles} Presence publishers, "
                     f"{len(reachable)} answering, {args.vehicles - len(reachable)} silent (unreachable)")
        elif companions:
            extra = (f"; companions registered: {len(reachable)} answering, {args.vehicles - len(reachable)} "
                     "blackholes")
        else:
            extra = "; no companion registered"
        print(f"# bench_ground: {args.vehicles} members at {args.rate:g} Hz on the team link, "
              f"{wall:.0f} s{extra}")
        print(f"# {machine()}")
        rows = [[name, len(v), f"{1e3 * pct(v, 0.5):.1f}", f"{1e3 * pct(v, 0.99):.1f}", "<= 50"]
                for name, v in lat.items()]
        rows.append(["WebSocket snapshot (feed -> socket)", len(lat_ws), f"{1e3 * pct(lat_ws, 0.5):.1f}",
                     f"{1e3 * pct(lat_ws, 0.95):.1f} (p95)", "<= 250 (p95)"])
        rows.append(["WebSocket update interval", len(intervals), f"{1e3 * pct(intervals, 0.5):.1f}",
                     f"{1e3 * pct(intervals, 0.95):.1f} (p95)", "<= 250 (p95)"])
        if cmd:
            rows.append(["command to a reachable vehicle (pause)", len(cmd), f"{1e3 * pct(cmd, 0.5):.1f}",
                         f"{1e3 * pct(cmd, 0.99):.1f}", "<= 200"])
        print(table(["measure", "n", "p50 ms", "p99 ms", "target ms"], rows))
        print()
        print(table(["service CPU (% of one core)", "snapshots/s"],
                    [[f"{cpu:.1f}", f"{snaps[0] / wall:.1f}"]]))
    finally:
        stop.set()
        http.close()
        ophttp.close()
        ground.close()
        for c in reversed(children):
            if c.stdin is not None:
                c.stdin.close()
            c.kill()
            c.wait(10)
    return 0


if __name__ == "__main__":
    sys.exit(main())
