"""Bench (a): the model in real-time mode, 500 Hz main loop, for 60 s of wall time.

Flies take-off, a 20 m square and a hover while paced on the wall clock, then prints per task group the
call frequency and its standard deviation (seed 002 Table 2), the duty time average/min/max over
windows of 1000 calls (Sec. 5), the overruns, and the offset heuristics' load over the hyperperiod.

    python -m bench.bench_realtime [--duration 60]
"""

from __future__ import annotations

import argparse
import logging
import time

from autopilot_model.flights import goto, takeoff
from autopilot_model.scheduler import format_offset_report, offset_report
from autopilot_model.vehicle import Vehicle
from bench.common import machine, table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0, help="wall seconds to run (default 60)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    v = Vehicle.from_files(sensors="indoor", speedup=0.0)
    loop = v.start()
    v.run_for(1.0)  # warm-up in lockstep: the compiled kernels load on their first call
    v.clock.set_speedup(1.0)
    loop.stats.reset()
    t0 = time.perf_counter()
    deadline = t0 + args.duration
    takeoff(v, 5.0)
    corners = [(20.0, 0.0), (20.0, 20.0), (0.0, 20.0), (0.0, 0.0)]
    for n, e in corners:
        if time.perf_counter() > deadline - 5:
            break
        goto(v, (n, e, -5.0), 5.0)
    remaining = deadline - time.perf_counter()
    if remaining > 0:
        v.run_for(remaining)
    wall = time.perf_counter() - t0
    st = loop.stats
    st.flush()
    rows = []
    for g in ("events", "sensors", "estimation", "navigation", "control", "actuators", "core", "telemetry",
              "world"):
        s = st.group_summary(g)
        if not s.get("calls"):
            continue
        rows.append((g, s["calls"], s["freq_hz"], s["freq_std_hz"], s["avg_us"], s["min_us"], s["max_us"]))
    print(f"bench_realtime: {wall:.1f} s wall, {v.clock.now():.1f} s simulated, main loop 500 Hz")
    print(f"machine: {machine()}")
    headers = ("task group", "calls", "freq Hz", "std Hz", "duty avg us", "duty min us", "duty max us")
    print(table(headers, rows))
    print(f"overruns (iteration work > 2000 us): {st.overruns} of {st.iterations()} iterations; "
          f"worst iteration {st.worst_ns / 1000:.0f} us")
    print()
    print("offset assignment over the hyperperiod (load = functions called per iteration):")
    print(format_offset_report(offset_report(loop.schedule)))


if __name__ == "__main__":
    main()
