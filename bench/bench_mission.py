"""Bench: tracking on the reproduction of seed 000 Fig. 16, the scan-and-search flight.

Runs :func:`taskflight.fig16.reproduce` (the bundled model with the indoor sensor profile in its own
process, the companion with its behavior and mission layers, two operator break-ins) ``--runs`` times
at ``--speedup`` and prints, from each flight log, the control error of Sec. VII: the measured position
(LOCAL_POSITION_NED) against the streamed position setpoint at its autopilot time, horizontal max / RMS
and vertical max / RMS without the take-off (and without the landing and the joystick segments,
which stream velocities). Seed 000 measured 39.1 / 14.1 cm and 19.2 / 5.4 cm in a real flight.

    python -m bench.bench_mission [--runs 3] [--speedup 2] [--out DIR]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from bench.common import machine, table
from taskflight.fig16 import reproduce


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=3, help="flights (default 3)")
    p.add_argument("--speedup", type=float, default=2.0, help="the model's speed-up (default 2)")
    p.add_argument("--out", default=None, metavar="DIR", help="keep the logs, PNGs and tables here")
    args = p.parse_args()
    rows = []
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench-mission-"))
    for i in range(args.runs):
        r = reproduce(out / f"run{i + 1}", args.speedup)
        t = r.tracking
        print(f"  run {i + 1}: {'OK' if r.ok else 'FAILED ' + '; '.join(r.problems)}", file=sys.stderr)
        if t is not None:
            rows.append((i + 1, "yes" if r.ok else "no", t.compared, t.h_max_cm, t.h_rms_cm, t.v_max_cm,
                         t.v_rms_cm, len(r.skipped), r.wall_s))
    print(f"# bench_mission ({machine()}), model at {args.speedup:g}x, indoor sensors; logs in {out}\n")
    print(table(["run", "ok", "setpoints", "H max cm", "H RMS cm", "V max cm", "V RMS cm", "skipped wp",
                 "wall s"], rows))
    if rows:
        print(f"\nworst: H max {max(r[3] for r in rows):.1f} cm, H RMS {max(r[4] for r in rows):.1f} cm, "
              f"V max {max(r[5] for r in rows):.1f} cm, V RMS {max(r[6] for r in rows):.1f} cm "
              f"(targets: at most half of seed 000's: 19.6 / 7.1 / 9.6 / 2.7 cm); "
              f"mean H RMS {statistics.mean(r[4] for r in rows):.1f} cm")
    return 0 if all(r[1] == "yes" for r in rows) and rows else 1


if __name__ == "__main__":
    start = time.monotonic()
    code = main()
    print(f"\n(wall {time.monotonic() - start:.0f} s)")
    sys.exit(code)
