"""Bench (c): tracking error of the true position against P_d on the 50 m square at 5 m/s.

Two disturbance profiles, both with gusts and sensor noise on, the estimator (not the truth) in the loop:

* ``indoor``: like seed 000's flight: position from a motion-capture-grade source (about 1 cm), gusts up
  to 1 m/s. Targets: horizontal RMS <= 7 cm and max <= 20 cm; vertical RMS <= 3 cm and max <= 10 cm
  (seed 000 reports 14.1/39.1 cm and 5.4/19.2 cm in real flight).
* ``outdoor``: GPS-grade position (10 Hz, 0.1 s latency, metre-level correlated error) and a 3.6 m/s mean
  wind with gusts up to 3 m/s.

    python -m bench.bench_tracking [--seeds 3]
"""

from __future__ import annotations

import argparse
import logging

from autopilot_model.airframe import load_airframe
from autopilot_model.flights import fly_square
from autopilot_model.vehicle import Vehicle
from bench.common import machine, table

PROFILES = {
    "indoor": {"sensors": "indoor", "wind_mean": (0.0, 0.0, 0.0), "gust_sigma": 0.5, "gust_max": 1.0},
    "outdoor": {"sensors": "outdoor", "wind_mean": (3.0, 2.0, 0.0), "gust_sigma": 1.5, "gust_max": 3.0},
}


def fly(profile: str, seed: int) -> dict[str, float]:
    cfg = PROFILES[profile]
    af = load_airframe()
    af.wind_mean = cfg["wind_mean"]
    af.gust_sigma = cfg["gust_sigma"]
    af.gust_max = cfg["gust_max"]
    v = Vehicle(af, sensors=cfg["sensors"], seed=seed)
    return fly_square(v).summary()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="flights per profile (different noise and gusts)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    rows = []
    for profile in PROFILES:
        runs = [fly(profile, seed) for seed in range(args.seeds)]
        worst = {k: max(r[k] for r in runs) for k in ("h_rms", "h_max", "v_rms", "v_max")}
        mean = {k: sum(r[k] for r in runs) / len(runs) for k in ("h_rms", "v_rms")}
        rows.append((profile, len(runs), mean["h_rms"] * 100, worst["h_rms"] * 100, worst["h_max"] * 100,
                     mean["v_rms"] * 100, worst["v_rms"] * 100, worst["v_max"] * 100))
    print("bench_tracking: 50 m square at 5 m/s, 10 m altitude; truth minus P_d, in cm")
    print(f"machine: {machine()}")
    print(table(("profile", "flights", "h RMS mean", "h RMS worst", "h max", "v RMS mean", "v RMS worst",
                 "v max"), rows))
    print("targets (indoor): h RMS <= 7, h max <= 20, v RMS <= 3, v max <= 10")


if __name__ == "__main__":
    main()
