"""Bench: ``taskflight up`` for N = 12, 25 and 50 vehicles.

Each configuration starts a fleet as ``taskflight up`` does (:class:`taskflight.up.Up`, in this process:
the models in one process, the companions K to a process on one team link (``taskflight companion-host``;
K = 1: one ``taskflight companion`` process each), the ground service when it is installed), on a free
block of instance numbers, and measures

* start-up: wall seconds from the start to every vehicle ready (each companion's MAVLink link connected
  and every vehicle's row heard on the team link, the ground service listing them);
* over ``--measure`` wall seconds after a ``--settle`` pause, from /proc: the CPU share (% of ONE core:
  user + system time over the interval) and the resident memory (VmRSS) of the models' process, of the
  companions (sum, and per companion) and of the ground service;
* stop: wall seconds of ``Up.stop`` (the ground service, the companions' processes, the models; each
  given 10 s before SIGKILL);
* simulated seconds per wall second: vehicle 1's autopilot clock (its companion's estimate of the
  autopilot time, ``GET /status`` link.autopilot_time_s) advanced over the interval, per wall second.

The vehicles sit on the ground idle (the models, companions and team link doing their periodic work: the
steady cost of a fleet). Then, with the ground service, the team exercise of :mod:`bench.up_exercise` (a
visit and a patrol line per vehicle through REST): how many were flown, in how long, tasks done per
minute and the simulated seconds per wall second while the fleet flies.

``--configs N:SPEEDUP[:NICE[:K]],...`` (default ``12:1,25:1,50:1,50:0``; speedup 0
is lockstep, as fast as the machine goes, the companions following autopilot time; K the companions per
process, default ``taskflight up``'s: as many hosts as cores). The table is printed at the end.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import socket
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from bench.common import machine, table
from bench.up_exercise import Exercise, run
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
    per_process: int = 0
    processes: int = 0
    stop_s: float = float("nan")
    exercise: Exercise | None = None

    @property
    def mb_per_vehicle(self) -> float:
        """Resident memory of the whole fleet (models, companions, ground service) per vehicle."""
        ground = 0.0 if math.isnan(self.ground_mb) else self.ground_mb
        return (self.models_mb + self.comp_mb + ground) / self.n


def autopilot_time(up: Up) -> float:
    v = up.vehicles[0]
    return float(http_json("GET", v.control_url + "/status", up.control_token)["link"]["autopilot_time_s"])


def measure(n: int, speedup: float, settle_s: float, measure_s: float, ground: bool, nice: int = 0,
            per_process: int | None = None, exercise_s: float = 0.0) -> Row:
    with tempfile.TemporaryDirectory(prefix="bench-up-") as tmp:
        opts = UpOptions(vehicles=n, state_dir=Path(tmp), speedup=speedup, base_instance=free_base(n),
                         ground=ground, ground_port=free_ports(1, socket.SOCK_STREAM)[0], persist=False,
                         ready_timeout_s=60 + 6.0 * n,
                         companion_nice=nice, companions_per_process=per_process)
        up = Up(opts)
        row: Row | None = None
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
            row = Row(n, speedup, up.startup_s, cpu["models"], mem["models"], cpu["companions"],
                      mem["companions"], cpu["ground"] if ground else float("nan"),
                      mem["ground"] if ground else float("nan"), (sim1 - sim0) / wall,
                      f"died: {dead}" if dead else "", nice, opts.per_process, len(up.companions()))
            if exercise_s > 0 and up.ground_url is not None:
                print(f"N = {n}: the team exercise (a visit and a patrol per vehicle) ...", file=sys.stderr,
                      flush=True)
                try:
                    row.exercise = run(up.ground_url, up.tokens["operator"][0], n, exercise_s,
                                       lambda: autopilot_time(up))
                except Exception as exc:  # a row says what failed; the next one runs
                    row.exercise = Exercise(n, 0, 0, 0.0, 0.0, f"failed: {exc!r}"[:200])
        except Exception as exc:  # an UpError (not ready in time, a child died) or a bug: the row says which
            first = str(exc).splitlines()[0] if isinstance(exc, UpError) else repr(exc)
            nan = float("nan")
            row = Row(n, speedup, nan, nan, nan, nan, nan, nan, nan, nan, note=f"failed: {first[:100]}",
                      nice=nice, per_process=opts.per_process)
        finally:
            t_stop = time.monotonic()
            up.stop()
            if row is not None:
                row.stop_s = time.monotonic() - t_stop
                left = [c.name for c in up.children if c.running]
                if left:
                    row.note += f" left running: {left}"
        return row


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--configs", default="12:1,25:1,50:1,50:0", help="N:SPEEDUP[:NICE[:K]],... (speedup 0: "
                   "lockstep; NICE: the companions' niceness, --companion-nice; K: companions per process, "
                   "--companions-per-process, default taskflight up's)")
    p.add_argument("--settle", type=float, default=10.0, help="wall seconds after READY before measuring")
    p.add_argument("--measure", type=float, default=20.0, help="wall seconds measured")
    p.add_argument("--no-ground", action="store_true", help="leave the ground service out")
    p.add_argument("--exercise", type=float, default=300.0, help="wall seconds each phase of the team "
                   "exercise may take (visits, then patrols; 0: no exercise; it needs the ground service)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    ground = ground_available() and not args.no_ground
    rows = []
    for item in args.configs.split(","):
        n, k, *rest = item.split(":")
        nice = int(rest[0]) if rest and rest[0] else 0
        per = int(rest[1]) if len(rest) > 1 else None
        print(f"N = {n}, speedup {k}, companions' niceness {nice}, per process {per or 'default'} ...",
              file=sys.stderr, flush=True)
        rows.append(measure(int(n), float(k), args.settle, args.measure, ground, nice, per, args.exercise))
        print(rows[-1], file=sys.stderr, flush=True)
    print(f"taskflight up: {machine()}; idle fleet on the ground, measured {args.measure:g} s after "
          f"{args.settle:g} s; CPU in % of one core; ground service {'on' if ground else 'off'}")
    print(table(["N", "speedup", "nice", "K (processes)", "start-up s", "stop s", "models CPU %", "models MB",
                 "companions CPU % (per vehicle)", "companions MB (per vehicle)", "ground CPU %", "ground MB",
                 "MB per vehicle in all", "sim s / wall s", "note"],
                [[r.n, "lockstep" if r.speedup == 0 else f"{r.speedup:g}", r.nice,
                  f"{r.per_process} ({r.processes})", f"{r.startup_s:.1f}", f"{r.stop_s:.1f}",
                  f"{r.models_cpu:.1f}", f"{r.models_mb:.0f}",
                  f"{r.comp_cpu:.1f} ({r.comp_cpu / r.n:.1f})", f"{r.comp_mb:.0f} ({r.comp_mb / r.n:.1f})",
                  f"{r.ground_cpu:.1f}", f"{r.ground_mb:.0f}",
                  f"{r.mb_per_vehicle:.1f}",
                  f"{r.sim_rate:.2f}", r.note] for r in rows]))
    done = [r for r in rows if r.exercise is not None]
    if done:
        print("\nthe team exercise: a visit, then a patrol line, per vehicle, through the ground service's "
              "REST API (bench/up_exercise.py)")
        print(table(["N", "speedup", "visits done", "patrols flown", "wall s", "sim s / wall s",
                     "tasks per min", "note"],
                    [[r.n, "lockstep" if r.speedup == 0 else f"{r.speedup:g}",
                      f"{e.visits_done}/{e.vehicles}", f"{e.patrols_flown}/{e.vehicles}", f"{e.wall_s:.0f}",
                      f"{e.sim_s / e.wall_s:.2f}" if e.wall_s else "-", f"{e.tasks_per_min:.1f}",
                      e.note[:120]]
                     for r in done if (e := r.exercise) is not None]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
