"""``taskflight demo``: the main job on embedded defaults.

Flies the bundled model through take-off, a square and a landing in lockstep and prints a report
(tracking error of the truth against P_d, simulated speed, scheduler statistics). With the MAVLink
side present the same vehicle can be flown from a ground station: ``taskflight autopilot``.
"""

from __future__ import annotations

import argparse
import logging
import time

log = logging.getLogger(__name__)


def add_model_arguments(p: argparse.ArgumentParser) -> None:
    """Options shared by every command that builds a vehicle."""
    p.add_argument("--airframe", default=None, help="airframe YAML (default: the bundled Quad X)")
    p.add_argument("--modules", default=None, help="module library YAML (default: the bundled one)")
    p.add_argument("--sensors", choices=("indoor", "outdoor", "perfect"), default=None,
                   help="sensor profile (default: the airframe's)")
    p.add_argument("--truth", action="store_true", help="controllers use ground truth (debugging)")
    p.add_argument("--speedup", type=float, default=None,
                   help="simulated seconds per wall second; 0 = lockstep as fast as possible")
    p.add_argument("--seed", type=int, default=0, help="random seed of noise and gusts")


def add_demo_arguments(p: argparse.ArgumentParser) -> None:
    add_model_arguments(p)
    p.add_argument("--side", type=float, default=50.0, help="side of the square (m)")
    p.add_argument("--speed", type=float, default=5.0, help="speed along the square (m/s)")
    p.add_argument("--alt", type=float, default=10.0, help="flight altitude (m)")
    p.add_argument("--stats", action="store_true", help="print the scheduler statistics too")


def run_demo(args: argparse.Namespace) -> int:
    from autopilot_model.flights import FlightError, fly_square
    from autopilot_model.vehicle import Vehicle
    from taskflight_common.yamlio import ConfigError

    try:
        v = Vehicle.from_files(args.airframe, args.modules, sensors=args.sensors, use_truth=args.truth,
                               speedup=args.speedup if args.speedup is not None else 0.0, seed=args.seed)
        v.start()
    except (ConfigError, ValueError) as exc:
        log.error("%s", exc)
        return 2
    t0 = time.perf_counter()
    try:
        rec = fly_square(v, args.side, args.speed, args.alt, progress=lambda m: log.info("demo: %s", m))
    except FlightError as exc:
        log.error("demo flight failed: %s", exc)
        return 1
    wall = time.perf_counter() - t0
    s = rec.summary()
    sim = v.clock.now()
    lines = [
        "",
        "Taskflight demo flight: take-off, square, landing",
        f"  airframe {v.airframe.name}, sensors {v.sensor_profile}, estimator "
        f"{'truth' if v.estimator.use_truth else 'INS/AHRS'}",
        f"  square {args.side:g} m at {args.speed:g} m/s, altitude {args.alt:g} m",
        f"  simulated {sim:.1f} s in {wall:.2f} s wall ({sim / wall:.1f}x real time)",
        "  tracking error of the true position against P_d on the square:",
        f"    horizontal RMS {s['h_rms'] * 100:.1f} cm, max {s['h_max'] * 100:.1f} cm",
        f"    vertical   RMS {s['v_rms'] * 100:.1f} cm, max {s['v_max'] * 100:.1f} cm",
        f"  landed and disarmed: {not v.nav.armed}; battery used {v.battery.consumed_mah:.0f} mAh",
    ]
    if args.stats and v.loop is not None:
        lines += ["", v.loop.stats.table()]
    print("\n".join(lines))  # the command's output (this is the CLI, not library code)
    return 0
