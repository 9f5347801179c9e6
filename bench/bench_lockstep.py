"""Bench (b): lockstep speed, simulated seconds per wall second, one vehicle at 500 Hz.

Runs the model as fast as it can (speedup 0) on one core through a hover and the 50 m square, and
prints the ratio with the mean wall cost of an iteration and of each task group.

With ``TASKFLIGHT_ARDUCOPTER`` set (or ``--arducopter``), ArduPilot's own copter SITL runs in the same
run at its highest speed-up (``--speedup 10000``: as fast as it goes) and is measured the same way:
simulated seconds per wall second from the ``time_boot_ms`` of its SYSTEM_TIME, on the ground and
hovering at 10 m in GUIDED (the model's lockstep speed beside ArduCopter's top speed).

    python -m bench.bench_lockstep [--seconds 120] [--arducopter]
"""

from __future__ import annotations

import argparse
import logging
import os
import tempfile
import time
from pathlib import Path

from autopilot_model.flights import fly_square, takeoff
from autopilot_model.vehicle import Vehicle
from bench.common import machine, table


def arducopter_rates(window_s: float = 8.0) -> list[tuple[str, float, float, float]]:
    """(state, simulated s, wall s, ratio) of ArduCopter SITL at its top speed: on the ground, hovering."""
    from harness.autopilot import start_autopilot
    from harness.observer import GUIDED, M

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        ap = start_autopilot("arducopter", Path(tmp), 10000.0)
        gcs = ap.gcs
        try:
            def measure(state: str) -> None:
                t0, b0 = time.perf_counter(), gcs.fresh("SYSTEM_TIME").time_boot_ms
                time.sleep(window_s)  # a bench: the wall window is the measure
                t1, b1 = time.perf_counter(), gcs.fresh("SYSTEM_TIME").time_boot_ms
                sim = (b1 - b0) / 1000.0
                rows.append((f"ArduCopter SITL, {state}", sim, t1 - t0, sim / (t1 - t0)))

            def fix() -> bool:
                g = gcs.last.get("GPS_RAW_INT")
                return g is not None and g.fix_type >= 3

            def up() -> bool:
                p = gcs.last.get("GLOBAL_POSITION_INT")
                return p is not None and p.relative_alt > 9500

            gcs.wait(fix, 60, "GPS fix")
            measure("on the ground")
            gcs.wait(lambda: gcs.set_mode(GUIDED) == 0, 30, "GUIDED")
            gcs.wait(lambda: gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0, 60, "armed (pre-arm)")
            assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10) == 0
            gcs.wait(up, 60, "10 m up")
            measure("hovering at 10 m (GUIDED)")
        finally:
            ap.close()
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=120.0, help="simulated seconds of hover (default 120)")
    ap.add_argument("--arducopter", action="store_true",
                    default=bool(os.environ.get("TASKFLIGHT_ARDUCOPTER")),
                    help="also measure ArduCopter SITL's top speed (default: TASKFLIGHT_ARDUCOPTER set)")
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
    if args.arducopter:
        print()
        print("ArduPilot's copter SITL (C++) at its highest speed-up, same machine, same run:")
        print(table(("flight", "simulated s", "wall s", "sim s per wall s"), arducopter_rates()))
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
