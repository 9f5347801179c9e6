"""A team exercise on a running ``taskflight up`` fleet, through the ground service's REST API.

Seed 003 Sec. II's operator tasks, one of each per vehicle: every vehicle is given a visit 15 m north of
where it sits, then (once the visits are done) a patrol line 10 m long further north; the team allocates
them (seed 003 Sec. III). A visit counts when its task is ``done``; a patrol counts as flown when its holder
has been seen within :data:`END_M` of both ends (vehicle positions from ``GET /api/vehicles``, sampled at
5 Hz: the vehicle turns at the ends, so it is slow there), then it is cancelled. The figure is the tasks
done per minute of wall time: the visits done plus the patrols flown, over the exercise.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from taskflight.team_tasking import GroundTasking, http_json
from taskflight_common.geo import geodetic_to_ned, ned_to_geodetic

log = logging.getLogger(__name__)

#: how close to a patrol's end its holder must have been seen (m)
END_M = 1.5
VISIT_N = 15.0  # m north of the vehicle
PATROL_N = (20.0, 30.0)  # m north of the vehicle: the patrol line's two ends


@dataclass
class Exercise:
    vehicles: int
    visits_done: int
    patrols_flown: int
    wall_s: float
    sim_s: float
    note: str = ""

    @property
    def tasks_per_min(self) -> float:
        return 60.0 * (self.visits_done + self.patrols_flown) / self.wall_s if self.wall_s > 0 else 0.0


def _vehicles(base: str, token: str) -> list[dict[str, Any]]:
    return list(http_json("GET", base + "/api/vehicles", token)["vehicles"])


def run(base: str, token: str, n: int, timeout_s: float, clock: Callable[[], float]) -> Exercise:
    """The exercise on the ground service at ``base`` (operator ``token``) with ``n`` vehicles; each phase
    given ``timeout_s`` wall seconds. ``clock()`` is the autopilot time of one vehicle (simulated seconds)."""
    t0, sim0 = time.monotonic(), clock()
    tasking = GroundTasking(base, token)  # the REST calls the team demo makes
    homes: dict[int, tuple[float, float, float]] = {}
    for v in _vehicles(base, token):
        p = v.get("position")
        if p is not None:
            homes[int(v["id"])] = (p["lat"], p["lon"], 0.0)
    if len(homes) != n:
        return Exercise(n, 0, 0, 0.0, 0.0, f"{len(homes)} of {n} vehicles have a position")
    visits = [tasking.add("visit", [ned_to_geodetic(h, VISIT_N, 0.0, 0.0)[:2]], f"visit {i}")[0]
              for i, h in homes.items()]
    deadline = time.monotonic() + timeout_s
    done: set[int] = set()
    last = time.monotonic()
    while len(done) < n and time.monotonic() < deadline:
        done = {t.id for t in tasking.tasks() if t.id in visits and t.state == "done"}
        if time.monotonic() - last > 5.0:
            log.info("visits done: %d of %d", len(done), n)
            last = time.monotonic()
        time.sleep(0.5)
    ends: dict[int, list[tuple[float, float, float]]] = {}
    for i, h in homes.items():
        pts = [ned_to_geodetic(h, north, 0.0, 0.0) for north in PATROL_N]
        ends[tasking.add("patrol_line", [p[:2] for p in pts], f"patrol {i}")[0]] = pts
    seen: dict[int, list[float]] = {t: [float("inf"), float("inf")] for t in ends}
    deadline = time.monotonic() + timeout_s
    flown: set[int] = set()
    while len(flown) < n and time.monotonic() < deadline:
        for v in _vehicles(base, token):
            t, p = v.get("task"), v.get("position")
            if t is None or p is None or int(t) not in ends:
                continue
            for k, e in enumerate(ends[int(t)]):
                north, east, _ = geodetic_to_ned(e, p["lat"], p["lon"], 0.0)
                seen[int(t)][k] = min(seen[int(t)][k], (north * north + east * east) ** 0.5)
            if max(seen[int(t)]) <= END_M and int(t) not in flown:
                flown.add(int(t))
                tasking.cancel(int(t))
        if time.monotonic() - last > 5.0:
            log.info("patrols flown: %d of %d", len(flown), n)
            last = time.monotonic()
        time.sleep(0.2)
    for t in set(ends) - flown:
        tasking.cancel(t)
    wall = time.monotonic() - t0
    note = "" if len(done) == n and len(flown) == n else \
        f"not flown: visits {sorted(set(visits) - done)}, patrols {sorted(set(ends) - flown)}"
    return Exercise(n, len(done), len(flown), wall, clock() - sim0, note)
