"""Bench: the true horizontal speed in an outdoor (GPS) hover, beside the square's tracking.

The vehicle takes off to 10 m with the outdoor profile of :mod:`bench.bench_tracking` (GPS-grade position:
10 Hz, 0.1 s latency, metre-level correlated error; 3.6 m/s wind, gusts up to 3 m/s), settles 5 s and
holds position for 60 s; the figure is the median and 95th percentile of the *true* horizontal speed,
sampled at 50 Hz and pooled over the seeds. The same parameter sets then fly the 50 m square of
``bench_tracking`` (indoor and outdoor; true position minus P_d), so a hover figure is never bought with
tracking. Rows:

* ``filter off``: PSC_VELXY_FLTE = PSC_VELXY_FLTD = 0, the model's velocity loop before the filter;
* ``filter 5 Hz``: ArduCopter's defaults (the model's defaults), the error and its derivative low-pass
  filtered as ``AC_PID_2D`` does;
* ``ArduCopter gains``: ArduCopter's PSC_POSXY_P 1, PSC_VELXY_P 2, I 1, D 0.25 with the 5 Hz filters, for
  reference (the model's defaults are 3, 6, 4, 0).

    python -m bench.bench_hover [--seeds 3] [--hover-s 60]
"""

from __future__ import annotations

import argparse
import logging
import math
import statistics

from autopilot_model.airframe import load_airframe
from autopilot_model.flights import fly_square, takeoff
from autopilot_model.physics.quadrotor import VX, VY
from autopilot_model.vehicle import Vehicle
from bench.bench_tracking import PROFILES
from bench.common import machine, pct, table

CONFIGS: dict[str, dict[str, float]] = {
    "filter off (before)": {"PSC_VELXY_FLTE": 0.0, "PSC_VELXY_FLTD": 0.0},
    "filter 5 Hz (ArduCopter default)": {},
    "ArduCopter gains, filter 5 Hz": {"PSC_POSXY_P": 1.0, "PSC_VELXY_P": 2.0, "PSC_VELXY_I": 1.0,
                                      "PSC_VELXY_D": 0.25},
}


def vehicle(profile: str, seed: int, params: dict[str, float]) -> Vehicle:
    cfg = PROFILES[profile]
    af = load_airframe()
    af.wind_mean = cfg["wind_mean"]
    af.gust_sigma = cfg["gust_sigma"]
    af.gust_max = cfg["gust_max"]
    v = Vehicle(af, sensors=cfg["sensors"], seed=seed)
    for name, value in params.items():
        v.params.set(name, value)
    return v


def hover_speeds(seed: int, params: dict[str, float], hover_s: float) -> list[float]:
    """True horizontal speeds (m/s, 50 Hz) over ``hover_s`` of an outdoor position hold at 10 m."""
    v = vehicle("outdoor", seed, params)
    takeoff(v, 10.0)
    v.run_for(5.0)
    x = v.world.x
    out = []
    end = v.clock.now() + hover_s
    while v.clock.now() < end:
        v.run_for(0.02)
        out.append(math.hypot(x[VX], x[VY]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="flights per row (different noise and gusts)")
    ap.add_argument("--hover-s", type=float, default=60.0, help="simulated seconds of hover per flight")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    rows = []
    for name, params in CONFIGS.items():
        speeds: list[float] = []
        medians = []
        for seed in range(args.seeds):
            s = hover_speeds(seed, params, args.hover_s)
            speeds += s
            medians.append(statistics.median(s))
        track = {}
        for profile in ("indoor", "outdoor"):
            runs = [fly_square(vehicle(profile, seed, params)).summary() for seed in range(args.seeds)]
            track[profile] = (sum(r["h_rms"] for r in runs) / len(runs) * 100,
                              max(r["h_max"] for r in runs) * 100)
        rows.append((name, statistics.median(speeds), pct(speeds, 0.95), max(medians), *track["indoor"],
                     *track["outdoor"]))
    print(f"bench_hover: outdoor (GPS) hover at 10 m, {args.hover_s:g} s x {args.seeds} seeds, "
          "true horizontal speed (m/s); 50 m square at 5 m/s, truth minus P_d (cm)")
    print(f"machine: {machine()}")
    print(table(("parameters", "hover median", "hover p95", "hover median worst seed", "indoor h RMS",
                 "indoor h max", "outdoor h RMS", "outdoor h max"), rows))


if __name__ == "__main__":
    main()
