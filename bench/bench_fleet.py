"""Bench of issue 12 item 8: many vehicles' models in one process on one clock (:mod:`autopilot_model.fleet`).

For N = 1, 3, 12 at real time and N = 12, 50 in lockstep, a fleet process (this script with ``--child``)
runs a warm-up, then a measured wall interval, and reports: its CPU share (``os.times``, user + system,
over the interval, in percent of one core), its memory (RSS), simulated seconds per wall second, the main
loop's period lateness (wall time by which a period started after its deadline: p50, p99; real time only)
and the periods it gave up (slips). Meanwhile this process is a ground station on every vehicle's UDP
port (pymavlink, one ``udpout`` link each, GCS heartbeats at 1 Hz, the model's default telemetry set
streaming back) and counts the vehicles heard: a HEARTBEAT from system id i+1 on vehicle i's port.

For comparison, the single-vehicle model (``python -m autopilot_model.sitl``, paced by sleeping and then
spinning through the last millisecond of each period) is measured the same way from outside
(``/proc/PID/stat``), with one ground station.

    python -m bench.bench_fleet [--window 10] [--warmup 3] [--no-baseline]
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import random
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

from bench.common import machine, table

ROOT = Path(__file__).resolve().parents[1]
#: (vehicles, speedup) measured by default; speedup 0 = lockstep
CASES = ((1, 1.0), (3, 1.0), (12, 1.0), (12, 0.0), (50, 0.0))


# --- the fleet process ----------------------------------------------------------------------------------
def _rss_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def child(args: argparse.Namespace) -> int:
    """Run a fleet: READY, warm-up, measured interval, one ``RESULT {json}`` line."""
    from autopilot_model.fleet import Fleet

    logging.basicConfig(level=logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp, \
            Fleet(args.vehicles, args.speedup, base_instance=args.base, state_dir=tmp, persist=False,
                  url_templates=["tcpin:127.0.0.1:{tcp}", "udpin:127.0.0.1:{udp}"]) as fleet:
        print("READY", flush=True)

        def run_for(wall_s: float) -> None:
            stop = threading.Event()
            timer = threading.Timer(wall_s, stop.set)
            timer.start()
            fleet.run(None, stop)
            timer.join()

        run_for(args.warmup)
        fleet.reset_stats()
        r0, c0, t0 = fleet.rounds, os.times(), time.perf_counter()
        run_for(args.window)
        wall = time.perf_counter() - t0
        c1 = os.times()
        cpu = (c1.user - c0.user) + (c1.system - c0.system)
        p50, p99 = fleet.lateness_quantiles((0.5, 0.99))
        result = {"cpu_pct": 100.0 * cpu / wall, "rss_mb": _rss_mb(), "wall_s": wall,
                  "sim_s": (fleet.rounds - r0) * fleet.period_us * 1e-6, "late_p50_us": p50 * 1e6,
                  "late_p99_us": p99 * 1e6, "slips": fleet.slips}
        print("RESULT " + json.dumps(result), flush=True)
    return 0


# --- the ground stations ----------------------------------------------------------------------------------
class Stations:
    """One pymavlink ground station per UDP port, pumped by a thread; vehicles heard by port."""

    def __init__(self, ports: list[int]) -> None:
        from pymavlink import mavutil

        mavutil.set_dialect("ardupilotmega")
        self.conns = [mavutil.mavlink_connection(f"udpout:127.0.0.1:{p}", source_system=255,
                                                 source_component=190) for p in ports]
        self.sysids: list[set[int]] = [set() for _ in ports]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="stations", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from pymavlink import mavutil

        hb_next = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= hb_next:
                hb_next = now + 1.0
                for c in self.conns:
                    c.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID,
                                         0, 0, 0)
            for i, c in enumerate(self.conns):
                while (m := c.recv_match(blocking=False)) is not None:
                    if m.get_type() == "HEARTBEAT":
                        self.sysids[i].add(m.get_srcSystem())
            time.sleep(0.005)

    def heard(self) -> int:
        """Vehicles whose port carried a HEARTBEAT from their own system id (i+1), and nobody else's."""
        return sum(1 for i, s in enumerate(self.sysids) if s == {i + 1})

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        for c in self.conns:
            c.close()


def _free_base(n: int) -> int:
    """A base instance (60..254-n) whose instances' TCP 5760+10i and UDP 14550+10i ports are all free."""
    def free(kind: int, port: int) -> bool:
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                return False
        return True

    rng = random.Random(os.getpid())
    for _ in range(50):
        base = rng.randrange(60, 255 - n)
        if all(free(socket.SOCK_STREAM, 5760 + 10 * i) and free(socket.SOCK_DGRAM, 14550 + 10 * i)
               for i in range(base, base + n)):
            return base
    raise RuntimeError(f"no block of {n} free instance numbers")


def _spawn(args: list[str]) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", ""))
                                                      if p), PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, *args], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, stdin=subprocess.DEVNULL)


def _wait_line(proc: subprocess.Popen[str], prefix: str, timeout_s: float) -> str:
    assert proc.stdout is not None
    end = time.monotonic() + timeout_s
    seen = []
    for line in proc.stdout:
        if line.startswith(prefix):
            return line.strip()
        seen.append(line.rstrip())
        if time.monotonic() > end:
            break
    proc.kill()
    raise RuntimeError(f"no {prefix} line; output: {' | '.join(seen[-8:])}")


def measure_fleet(n: int, speedup: float, warmup: float, window: float) -> dict[str, Any]:
    base = _free_base(n)
    proc = _spawn(["-m", "bench.bench_fleet", "--child", "--vehicles", str(n), "--speedup", str(speedup),
                   "--base", str(base), "--warmup", str(warmup), "--window", str(window)])
    try:
        t0 = time.perf_counter()
        _wait_line(proc, "READY", 180)
        startup = time.perf_counter() - t0
        stations = Stations([14550 + 10 * i for i in range(base, base + n)])
        try:
            result = json.loads(_wait_line(proc, "RESULT", warmup + window + 120).split(" ", 1)[1])
        finally:
            stations.close()
        result["heard"] = stations.heard()
        result["startup_s"] = startup
        return result
    finally:
        if proc.poll() is None:
            proc.terminate()
        proc.wait(30)
        if proc.stdout is not None:
            proc.stdout.close()


def _proc_cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _proc_rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def measure_single(warmup: float, window: float) -> dict[str, Any]:
    """The single-vehicle model process at real time, measured from outside."""
    base = _free_base(1)
    with tempfile.TemporaryDirectory() as tmp:
        proc = _spawn(["-m", "autopilot_model.sitl", "--instance", str(base), "--speedup", "1",
                       "--state-dir", tmp, "--no-persist", "--mavlink", f"tcpin:127.0.0.1:{5760 + 10 * base}",
                       "--mavlink", f"udpin:127.0.0.1:{14550 + 10 * base}"])
        try:
            _wait_line(proc, "READY", 120)
            assert proc.stdout is not None
            threading.Thread(target=proc.stdout.read, daemon=True).start()  # keep the pipe drained
            stations = Stations([14550 + 10 * base])
            try:
                time.sleep(warmup)  # a bench: the wall window is the measure
                c0, t0 = _proc_cpu_s(proc.pid), time.perf_counter()
                time.sleep(window)
                cpu, wall = _proc_cpu_s(proc.pid) - c0, time.perf_counter() - t0
                rss = _proc_rss_mb(proc.pid)
            finally:
                stations.close()
            heard = 1 if stations.sysids[0] == {base + 1} else 0
        finally:
            proc.terminate()
            proc.wait(30)
    return {"cpu_pct": 100.0 * cpu / wall, "rss_mb": rss, "sim_s": float("nan"), "wall_s": wall,
            "late_p50_us": float("nan"), "late_p99_us": float("nan"), "slips": "-", "heard": heard,
            "startup_s": float("nan")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--window", type=float, default=10.0, help="measured wall seconds per case (default 10)")
    ap.add_argument("--warmup", type=float, default=3.0, help="wall seconds before measuring (default 3)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the single-vehicle process baseline")
    ap.add_argument("--cases", default=None, help="N:SPEEDUP,... (default 1:1,3:1,12:1,12:0,50:0)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--vehicles", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--speedup", type=float, default=1.0, help=argparse.SUPPRESS)
    ap.add_argument("--base", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        sys.exit(child(args))
    logging.basicConfig(level=logging.WARNING)
    cases = CASES if args.cases is None else tuple(
        (int(c.split(":")[0]), float(c.split(":")[1])) for c in args.cases.split(","))
    rows = []
    if not args.no_baseline:
        r = measure_single(args.warmup, args.window)
        rows.append(("1 (single-vehicle process, spin pacing)", "real time", r))
    for n, speedup in cases:
        rows.append((str(n), "real time" if speedup == 1 else f"x{speedup:g}" if speedup else "lockstep",
                     measure_fleet(n, speedup, args.warmup, args.window)))
    print(f"bench_fleet: one fleet process per case, {args.window:g} s measured after {args.warmup:g} s, "
          "a ground station on every vehicle's UDP port")
    print(f"machine: {machine()}")
    headers = ("vehicles", "pacing", "CPU % of one core", "RSS MB", "sim s per wall s", "lateness p50 us",
               "lateness p99 us", "slips", "heard", "start-up s")
    out = []
    for n, pacing, r in rows:
        speed = r["sim_s"] / r["wall_s"]
        row = (n, pacing, r["cpu_pct"], r["rss_mb"], speed, r["late_p50_us"], r["late_p99_us"], r["slips"],
               f"{r['heard']}/{n.split()[0]}", r["startup_s"])
        out.append(tuple("-" if isinstance(c, float) and c != c else c for c in row))  # NaN: not measured
    print(table(headers, out))


if __name__ == "__main__":
    main()
