"""Bench (b) of issue 2: lockstep speed, simulated seconds per wall second, one vehicle at 500 Hz.

Runs the model as fast as it can (speedup 0) on one core through a hover and the 50 m square, and
prints the ratio with the mean wall cost of an iteration and of each task group. ArduPilot's own copter
SITL (C++) reaches about 53-59x on this kind of machine by the same measure.

    python -m bench.bench_lockstep [--seconds 120]
"""

from __future__ import annotations

import argparse
import logging
import time

from autopilot_model.flights import fly_square, takeoff
from autopilot_model.vehicle import Vehicle
from bench.common import machine, table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=120.0, help="simulated seconds of hover (default 120)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    rows = []
    for profile in ("indoor", "outdoor"):
        # warm-up (numba's compiled kernels load from the cache on the first call)
        Vehicle.from_files(sensors=profile).run_for(1.0)
        v = Vehicle.from_files(sensors=profile)
        takeoff(v, 10.0)
        v.start().stats.reset()
        t0 = time.perf_counter()
        v.run_for(args.seconds)
        wall = time.perf_counter() - t0
        per_iter_us = wall / args.seconds / 500 * 1e6
        rows.append((f"hover, {profile}", args.seconds, wall, args.seconds / wall, per_iter_us))
        v = Vehicle.from_files(sensors=profile)
        t0 = time.perf_counter()
        fly_square(v)
        wall = time.perf_counter() - t0
        sim = v.clock.now()
        per_iter_us = wall / sim / 500 * 1e6
        rows.append((f"take-off, 50 m square, land, {profile}", sim, wall, sim / wall, per_iter_us))
    print("bench_lockstep: one vehicle, 500 Hz main loop, lockstep (as fast as possible), one process")
    print(f"machine: {machine()}")
    print(table(("flight", "simulated s", "wall s", "sim s per wall s", "wall us per iteration"), rows))
    st = v.start().stats
    groups = []
    for g in ("sensors", "estimation", "navigation", "control", "actuators", "core", "world"):
        s = st.group_summary(g)
        if s["calls"]:
            groups.append((g, s["sim_hz"], s["avg_us"]))
    print()
    print("mean wall cost per call in the last flight:")
    print(table(("task group", "calls per sim s", "avg us"), groups))


if __name__ == "__main__":
    main()
