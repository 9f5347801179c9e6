"""The web UI with N vehicles (12 by default): the map's update rate and frame time, measured in the
browser.

``taskflight ground`` runs as its own process on a real multicast team link fed with N members' rows at
10 Hz (bench_ground's feed: the team wire format of seed 003 Sec. III-A, each member on a circle); Debian's
headless Chromium opens the UI, logs in and, over the window, the page's own counters
(``window.taskflight.stats``) give

* the map's update interval: the time between two snapshots drawn (the service sends them at 10 Hz);
* the drawing time of one snapshot (map, lists, vehicle panel);
* the frame time: the interval between two ``requestAnimationFrame`` callbacks (60 Hz is 16.7 ms).

A screenshot is saved to ``docs/figures/ui.png``. Run: ``python bench/bench_ui.py [--vehicles 12]``.
"""

from __future__ import annotations

import argparse
import tempfile
import threading
import time
from pathlib import Path

from bench.bench_ground import feed
from bench.common import machine, pct, table
from harness import ROOT
from harness.ground import OPERATOR, GroundProcess
from harness.team import new_team_url
from harness.ui import browser, foreign, login, missing, requested_urls


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, default=12)
    ap.add_argument("--seconds", type=float, default=20.0, help="measurement window")
    ap.add_argument("--screenshot", default=str(ROOT / "docs" / "figures" / "ui.png"))
    args = ap.parse_args()
    if missing():
        raise SystemExit(missing())
    team = new_team_url()
    ground = GroundProcess(Path(tempfile.mkdtemp(prefix="bench_ui")), team, {}).start()
    url = ground.url
    stop = threading.Event()
    feeder = threading.Thread(target=feed, args=(team, args.vehicles, 10.0, stop), daemon=True)
    feeder.start()
    d = browser()
    try:
        login(d, url, OPERATOR)
        deadline = time.monotonic() + 30
        while d.execute_script("return document.querySelectorAll('.vmarker[data-n]').length") < args.vehicles:
            if time.monotonic() > deadline:
                raise SystemExit("not every vehicle on the map")
            time.sleep(0.2)
        d.execute_script("document.querySelector('#fleet tbody tr').click()")
        # the whole fleet in view (Leaflet in Web Mercator: every marker at its latitude and longitude)
        d.execute_script("const m = window.taskflight.map; m.map.fitBounds(window.L.latLngBounds("
                         "[...m.vehicles.values()].map((v) => v.marker.getLatLng())).pad(0.2))")
        time.sleep(2.0)
        d.execute_script("const s = window.taskflight.stats; s.intervals.length = 0;"
                         "s.renderTimes.length = 0; s.frameTimes.length = 0;"
                         "s.snap0 = s.snapshots; s.render0 = s.renders;")
        time.sleep(args.seconds)
        s = d.execute_script("const s = window.taskflight.stats; return {iv: s.intervals,"
                             "rt: s.renderTimes, ft: s.frameTimes, snaps: s.snapshots - s.snap0,"
                             "renders: s.renders - s.render0};")
        Path(args.screenshot).parent.mkdir(parents=True, exist_ok=True)
        d.save_screenshot(args.screenshot)
        away = foreign(requested_urls(d), url)
    finally:
        d.quit()
        stop.set()
        ground.close()
    iv, rt, ft = s["iv"], s["rt"], s["ft"]
    rate = 1000.0 / (sum(iv) / len(iv)) if iv else 0.0
    print(f"# bench_ui: {args.vehicles} vehicles at 10 Hz on the team link, {args.seconds:.0f} s, "
          "headless Chromium")
    print(f"# {machine()}")
    rows = [["map update interval (ms)", pct(iv, 0.5), pct(iv, 0.95), pct(iv, 0.99), max(iv, default=0)],
            ["snapshot drawing time (ms)", pct(rt, 0.5), pct(rt, 0.95), pct(rt, 0.99), max(rt, default=0)],
            ["frame time, rAF (ms)", pct(ft, 0.5), pct(ft, 0.95), pct(ft, 0.99), max(ft, default=0)]]
    print(table(["measure", "p50", "p95", "p99", "max"], rows))
    print()
    print(table(["vehicles", "snapshots received", "drawn", "map update rate (Hz)", "requests off the host"],
                [[args.vehicles, s["snaps"], s["renders"], rate, len(away)]]))
    print(f"\nscreenshot: {args.screenshot}")
    return 0 if rate >= 5.0 and not away else 1


if __name__ == "__main__":
    raise SystemExit(main())
