"""Bench: many vehicles' models in one process on one clock (:mod:`autopilot_model.fleet`).

For N = 1, 3, 12, 50 at real time and N = 12, 50 in lockstep, a fleet process (this script with ``--child``)
runs a warm-up, then a measured wall interval, and reports: its CPU share (``os.times``, user + system,
over the interval, in percent of one core, and per vehicle and 2 ms period), its memory (RSS), simulated
seconds per wall second, the main loop's period lateness (wall time by which a period started after its
deadline: p50, p99; real time only) and the periods it gave up (slips). Meanwhile this process is a ground
station on every vehicle's UDP port (plain sockets, GCS heartbeats at 1 Hz, the model's default telemetry
set streaming back, only the MAVLink headers read) and counts the vehicles heard: a HEARTBEAT from system
id i+1 on vehicle i's port.

For comparison, the single-vehicle model (``python -m autopilot_model.sitl``) is measured the same way from
outside (``/proc/PID/stat``), with one ground station: paced by sleeping (its default) and with
``--spin-us 1000`` (sleeping, then spinning through the last millisecond of each period).

    python -m bench.bench_fleet [--window 10] [--warmup 3] [--no-baseline]
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import os
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any

from harness import ROOT

os.environ.setdefault("MAVLINK20", "1")

from bench.common import machine, pct, table
from taskflight_common.ports import free_base

#: (vehicles, speedup) measured by default; speedup 0 = lockstep
CASES = ((1, 1.0), (3, 1.0), (12, 1.0), (50, 1.0), (12, 0.0), (50, 0.0))


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
                  spin_s=args.spin_us * 1e-6,
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
        print("WINDOW", flush=True)
        r0, c0, t0 = fleet.rounds, os.times(), time.perf_counter()
        run_for(args.window)
        wall = time.perf_counter() - t0
        c1 = os.times()
        cpu = (c1.user - c0.user) + (c1.system - c0.system)
        p50, p99 = fleet.lateness_quantiles((0.5, 0.99))
        periods = (fleet.rounds - r0) * len(fleet)
        result = {"cpu_pct": 100.0 * cpu / wall, "rss_mb": _rss_mb(), "wall_s": wall,
                  "cpu_us_per_vehicle_period": 1e6 * cpu / max(periods, 1),
                  "sim_s": (fleet.rounds - r0) * fleet.period_us * 1e-6, "late_p50_us": p50 * 1e6,
                  "late_p99_us": p99 * 1e6, "slips": fleet.slips}
        print("RESULT " + json.dumps(result), flush=True)
    return 0


# --- the ground stations ----------------------------------------------------------------------------------
#: the datagram's kernel receive time (Linux SO_TIMESTAMPNS = SCM_TIMESTAMPNS)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
#: telemetry rate the stations ask every vehicle for (REQUEST_DATA_STREAM, all streams), Hz
STREAM_HZ = 10
ATTITUDE_ID = 30


class Stations:
    """A ground station per UDP port, on plain sockets pumped by a thread; vehicles heard by port.

    Each second it sends every port a GCS HEARTBEAT, the first two with a REQUEST_DATA_STREAM (all streams
    at :data:`STREAM_HZ`, as the tests' ground station asks), pymavlink-encoded. Of what comes back it reads
    only the MAVLink 2 headers (length, system id, message id), so that even 50 vehicles' telemetry in
    lockstep costs this process little of the core the fleet shares with it, and it keeps the kernel's
    receive time of every ATTITUDE: the telemetry's wall-clock timing, unaffected by this thread's delays."""

    def __init__(self, ports: list[int], targets: list[int] | None = None) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as m

        self.targets = targets or [i + 1 for i in range(len(ports))]
        mav = m.MAVLink(None, 255, 190)
        hb = mav.heartbeat_encode(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav)
        self.hb = hb
        self.hello = [hb + mav.request_data_stream_encode(t, 1, m.MAV_DATA_STREAM_ALL, STREAM_HZ, 1).pack(mav)
                      for t in self.targets]
        self.ports = ports
        self.socks = []
        for _ in ports:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            sock.bind(("127.0.0.1", 0))
            sock.setblocking(False)
            self.socks.append(sock)
        self.sysids: list[set[int]] = [set() for _ in ports]
        self.attitude_ns: list[list[int]] = [[] for _ in ports]
        self.messages = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="stations", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import selectors

        sel = selectors.DefaultSelector()
        for i, sock in enumerate(self.socks):
            sel.register(sock, selectors.EVENT_READ, i)
        hb_next = 0.0
        sent = 0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= hb_next:
                hb_next = now + 1.0
                sent += 1
                for sock, port, hello in zip(self.socks, self.ports, self.hello, strict=True):
                    # the request twice (a lost datagram), then heartbeats only: a repeated request
                    # restarts the streams' phase, which would show as jitter
                    sock.sendto(hello if sent <= 2 else self.hb, ("127.0.0.1", port))
            for key, _ in sel.select(0.05):
                sock, i = key.fileobj, key.data
                while True:
                    try:
                        data, anc, _flags, _addr = sock.recvmsg(4096, 64)  # type: ignore[union-attr]
                    except BlockingIOError:
                        break
                    stamp = 0
                    for level, kind, raw in anc:
                        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(raw) >= 16:
                            sec, nsec = struct.unpack("qq", raw[:16])
                            stamp = sec * 1_000_000_000 + nsec
                    self._headers(data, i, stamp)
        sel.close()

    def _headers(self, data: bytes, i: int, stamp_ns: int) -> None:
        """Walk the MAVLink 2 frames of one datagram: the sender of every HEARTBEAT (message id 0), the
        receive time of every ATTITUDE."""
        k, n = 0, len(data)
        while k + 10 <= n and data[k] == 0xFD:
            length, incompat, sysid = data[k + 1], data[k + 2], data[k + 5]
            msgid = data[k + 7] | data[k + 8] << 8 | data[k + 9] << 16
            if msgid == 0:
                self.sysids[i].add(sysid)
            elif msgid == ATTITUDE_ID and stamp_ns:
                self.attitude_ns[i].append(stamp_ns)
            self.messages += 1
            k += 12 + length + (13 if incompat & 1 else 0)

    def restart_timing(self) -> None:
        """Forget the ATTITUDE times so far (the measured interval starts)."""
        for times in self.attitude_ns:
            times.clear()

    def attitude_jitter_us(self, speedup: float) -> tuple[float, float]:
        """p50, p99 over every vehicle of |interval between two ATTITUDEs - its nominal 1/STREAM_HZ|."""
        nominal = 1e9 / STREAM_HZ / speedup
        dev = [abs((b - a) - nominal) / 1000.0 for times in self.attitude_ns
               for a, b in itertools.pairwise(times)]
        return pct(dev, 0.5), pct(dev, 0.99)

    def heard(self) -> int:
        """Vehicles whose port carried a HEARTBEAT from their own system id, and nobody else's."""
        return sum(1 for s, t in zip(self.sysids, self.targets, strict=True) if s == {t})

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        for sock in self.socks:
            sock.close()


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


def measure_fleet(n: int, speedup: float, warmup: float, window: float, spin_us: float = 0.0
                  ) -> dict[str, Any]:
    base = free_base(n)
    proc = _spawn(["-m", "bench.bench_fleet", "--child", "--vehicles", str(n), "--speedup", str(speedup),
                   "--base", str(base), "--warmup", str(warmup), "--window", str(window),
                   "--spin-us", str(spin_us)])
    try:
        t0 = time.perf_counter()
        _wait_line(proc, "READY", 180)
        startup = time.perf_counter() - t0
        stations = Stations([14550 + 10 * i for i in range(base, base + n)])
        try:
            _wait_line(proc, "WINDOW", warmup + 120)
            stations.restart_timing()
            result = json.loads(_wait_line(proc, "RESULT", window + 120).split(" ", 1)[1])
        finally:
            stations.close()
        result["heard"] = stations.heard()
        result["att_p50_us"], result["att_p99_us"] = (stations.attitude_jitter_us(speedup) if speedup
                                                      else (float("nan"), float("nan")))
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


def measure_single(warmup: float, window: float, spin_us: float = 0.0) -> dict[str, Any]:
    """The single-vehicle model process at real time, measured from outside."""
    base = free_base(1)
    with tempfile.TemporaryDirectory() as tmp:
        proc = _spawn(["-m", "autopilot_model.sitl", "--instance", str(base), "--speedup", "1",
                       "--state-dir", tmp, "--no-persist", "--mavlink", f"tcpin:127.0.0.1:{5760 + 10 * base}",
                       "--mavlink", f"udpin:127.0.0.1:{14550 + 10 * base}", "--spin-us", f"{spin_us:g}"])
        try:
            _wait_line(proc, "READY", 120)
            assert proc.stdout is not None
            threading.Thread(target=proc.stdout.read, daemon=True).start()  # keep the pipe drained
            stations = Stations([14550 + 10 * base], [base + 1])
            try:
                time.sleep(warmup)  # a bench: the wall window is the measure
                stations.restart_timing()
                c0, t0 = _proc_cpu_s(proc.pid), time.perf_counter()
                time.sleep(window)
                cpu, wall = _proc_cpu_s(proc.pid) - c0, time.perf_counter() - t0
                rss = _proc_rss_mb(proc.pid)
            finally:
                stations.close()
            heard = stations.heard()
            att = stations.attitude_jitter_us(1.0)
        finally:
            proc.terminate()
            proc.wait(30)
    return {"cpu_pct": 100.0 * cpu / wall, "rss_mb": rss, "sim_s": float("nan"), "wall_s": wall,
            "cpu_us_per_vehicle_period": 1e6 * cpu / (wall * 500),
            "late_p50_us": float("nan"), "late_p99_us": float("nan"), "slips": "-", "heard": heard,
            "att_p50_us": att[0], "att_p99_us": att[1],
            "startup_s": float("nan")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--window", type=float, default=10.0, help="measured wall seconds per case (default 10)")
    ap.add_argument("--warmup", type=float, default=3.0, help="wall seconds before measuring (default 3)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the single-vehicle process baseline")
    ap.add_argument("--cases", default=None,
                    help="N:SPEEDUP[:SPIN_US],... (default 1:1,3:1,12:1,50:1,12:0,50:0; SPIN_US: "
                         "microseconds spun before each deadline, default 0)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--vehicles", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--speedup", type=float, default=1.0, help=argparse.SUPPRESS)
    ap.add_argument("--base", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--spin-us", type=float, default=0.0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        sys.exit(child(args))
    logging.basicConfig(level=logging.WARNING)
    cases = [(n, k, 0.0) for n, k in CASES] if args.cases is None else [
        (int(f[0]), float(f[1]), float(f[2]) if len(f) > 2 else 0.0)
        for f in (c.split(":") for c in args.cases.split(","))]
    rows = []
    if not args.no_baseline:
        for spin in (0.0, 1000.0):
            r = measure_single(args.warmup, args.window, spin)
            pacing = "real time" + (f", spin {spin:g} us" if spin else "")
            rows.append(("1 (single-vehicle process)", pacing, r))
    for n, speedup, spin_us in cases:
        pacing = "real time" if speedup == 1 else f"x{speedup:g}" if speedup else "lockstep"
        if spin_us:
            pacing += f", spin {spin_us:g} us"
        rows.append((str(n), pacing, measure_fleet(n, speedup, args.warmup, args.window, spin_us)))
    print(f"bench_fleet: one fleet process per case, {args.window:g} s measured after {args.warmup:g} s, "
          "a ground station on every vehicle's UDP port")
    print(f"machine: {machine()}")
    headers = ("vehicles", "pacing", "CPU % of one core", "CPU us per vehicle-period", "RSS MB",
               "sim s per wall s", "lateness p50 us",
               "lateness p99 us", "ATTITUDE jitter p50 us", "ATTITUDE jitter p99 us", "slips", "heard",
               "start-up s")
    out = []
    for n, pacing, r in rows:
        speed = r["sim_s"] / r["wall_s"]
        row = (n, pacing, r["cpu_pct"], r["cpu_us_per_vehicle_period"], r["rss_mb"], speed, r["late_p50_us"],
               r["late_p99_us"], r["att_p50_us"], r["att_p99_us"], r["slips"],
               f"{r['heard']}/{n.split()[0]}", r["startup_s"])
        out.append(tuple("-" if isinstance(c, float) and c != c else c for c in row))  # NaN: not measured
    print(table(headers, out))


if __name__ == "__main__":
    main()
