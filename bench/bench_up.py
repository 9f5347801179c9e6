"""Bench: ``taskflight up`` for N = 3, 12 and 50 vehicles.

Each configuration starts a fleet as ``taskflight up`` does (:class:`taskflight.up.Up`, in this process:
the models in one process, one companion process per vehicle on one team link, the ground service when
it is installed), on a free block of instance numbers, and measures

* start-up: wall seconds from the start to every vehicle ready (each companion's MAVLink link connected
  and every vehicle's row heard on the team link, the ground service listing them);
* over ``--measure`` wall seconds after a ``--settle`` pause, from /proc: the CPU share (% of ONE core:
  user + system time over the interval) and the resident memory (VmRSS) of the models' process, of the
  companions (sum, and per companion) and of the ground service;
* simulated seconds per wall second: vehicle 1's autopilot clock (its companion's estimate of the
  autopilot time, ``GET /status`` link.autopilot_time_s) advanced over the interval, per wall second.

The vehicles sit on the ground idle (the models, companions and team link doing their periodic work: the
steady cost of a fleet). ``--configs N:SPEEDUP,...`` (default ``3:1,12:1,50:0``; speedup 0 is lockstep,
as fast as the machine goes, the companions following autopilot time). The table is printed at the end.
"""

from __future__ import annotations

import argparse
import os
import socket
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from bench.common import machine, table
from taskflight.team_tasking import http_json
from taskflight.up import Up, UpError, UpOptions, ground_available
from taskflight_common.ports import free_base, free_ports

TICK = os.sysconf("SC_CLK_TCK")
PAGE = os.sysconf("SC_PAGE_SIZE")


def cpu_ticks(pid: int) -> int:
    """user + system clock ticks of a process so far (0 once it is gone)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return 0
    return int(fields[11]) + int(fields[12])


def rss_mb(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/statm", encoding="ascii") as f:
            return int(f.read().split()[1]) * PAGE / 1e6
    except OSError:
        return float("nan")


@dataclass
class Row:
    n: int
    speedup: float
    startup_s: float
    models_cpu: float
    models_mb: float
    comp_cpu: float
    comp_mb: float
    ground_cpu: float
    ground_mb: float
    sim_rate: float
    note: str = ""
    nice: int = 0


def autopilot_time(up: Up) -> float:
    v = up.vehicles[0]
    return float(http_json("GET", v.control_url + "/status", up.control_token)["link"]["autopilot_time_s"])


def measure(n: int, speedup: float, settle_s: float, measure_s: float, ground: bool, nice: int = 0) -> Row:
    with tempfile.TemporaryDirectory(prefix="bench-up-") as tmp:
        opts = UpOptions(vehicles=n, state_dir=Path(tmp), speedup=speedup, base_instance=free_base(n),
                         ground=ground, ground_port=free_ports(1, socket.SOCK_STREAM)[0], persist=False,
                         ready_timeout_s=60 + 6.0 * n,
                         companion_nice=nice)
        up = Up(opts)
        try:
            up.start()
            time.sleep(settle_s)
            groups = {"models": [up.fleet], "companions": up.companions(),
                      "ground": [c for c in up.children if c.name == "ground"]}
            t0, sim0 = time.monotonic(), autopilot_time(up)
            ticks0 = {k: sum(cpu_ticks(c.pid or 0) for c in cs) for k, cs in groups.items()}
            time.sleep(measure_s)
            t1, sim1 = time.monotonic(), autopilot_time(up)
            ticks1 = {k: sum(cpu_ticks(c.pid or 0) for c in cs) for k, cs in groups.items()}
            wall = t1 - t0
            cpu = {k: 100.0 * (ticks1[k] - ticks0[k]) / TICK / wall for k in groups}
            mem = {k: sum(rss_mb(c.pid or 0) for c in cs) for k, cs in groups.items()}
            dead = [c.name for c in up.children if not c.running]
            return Row(n, speedup, up.startup_s, cpu["models"], mem["models"], cpu["companions"],
                       mem["companions"], cpu["ground"] if ground else float("nan"),
                       mem["ground"] if ground else float("nan"), (sim1 - sim0) / wall,
                       f"died: {dead}" if dead else "", nice)
        except UpError as exc:
            first = str(exc).splitlines()[0]
            return Row(n, speedup, float("nan"), *([float("nan")] * 7), note=f"failed: {first[:100]}",
                       nice=nice)
        finally:
            up.stop()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--configs", default="3:1,12:1,50:0,50:0:10", help="N:SPEEDUP[:NICE],... (speedup 0: "
                   "lockstep; NICE: the companions' niceness, --companion-nice)")
    p.add_argument("--settle", type=float, default=10.0, help="wall seconds after READY before measuring")
    p.add_argument("--measure", type=float, default=20.0, help="wall seconds measured")
    p.add_argument("--no-ground", action="store_true", help="leave the ground service out")
    args = p.parse_args(argv)
    ground = ground_available() and not args.no_ground
    rows = []
    for item in args.configs.split(","):
        n, k, *nice = item.split(":")
        print(f"N = {n}, speedup {k}, companions' niceness {nice or 0} ...", file=sys.stderr, flush=True)
        rows.append(measure(int(n), float(k), args.settle, args.measure, ground, int(nice[0]) if nice else 0))
        print(rows[-1], file=sys.stderr, flush=True)
    print(f"taskflight up: {machine()}; idle fleet on the ground, measured {args.measure:g} s after "
          f"{args.settle:g} s; CPU in % of one core; ground service {'on' if ground else 'off'}")
    print(table(["N", "speedup", "nice", "start-up s", "models CPU %", "models MB", "companions CPU % (each)",
                 "companions MB (each)", "ground CPU %", "ground MB", "sim s / wall s", "note"],
                [[r.n, "lockstep" if r.speedup == 0 else f"{r.speedup:g}", r.nice, f"{r.startup_s:.1f}",
                  f"{r.models_cpu:.1f}", f"{r.models_mb:.0f}",
                  f"{r.comp_cpu:.1f} ({r.comp_cpu / r.n:.1f})", f"{r.comp_mb:.0f} ({r.comp_mb / r.n:.0f})",
                  f"{r.ground_cpu:.1f}", f"{r.ground_mb:.0f}", f"{r.sim_rate:.2f}", r.note] for r in rows]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
