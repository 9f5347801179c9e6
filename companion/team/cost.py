"""The cost of a team task for a vehicle (seed 003 Sec. III-B).

Seed 003: "A UAV calculates the cost to complete a task by computing the Euclidian distance from its
current location to the point associated with the task ... the point where the UAV will first reach"
it; "the Euclidean distance can be considered a lower bound on the actual cost". :func:`euclidean` is that
cost (m); :class:`CostModel` is the better one, the flight time (s) under the vehicle's limits:

* horizontal leg: a trapezoidal speed profile from rest to rest, ``t = d/v + v/a`` when the vehicle
  reaches cruise (``d >= v^2/a``), else the triangular ``2 sqrt(d/a)``;
* vertical leg: ``|dz| / climb_speed``, added to the horizontal time (a SUM: the conservative choice, a
  copter that climbs to the task altitude then flies level; it keeps the Euclidean lower bound
  ``max(speed, climb_speed) * time >= euclidean distance``, tested).

Each kind (:mod:`companion.team.kinds`) gives its characteristic point (:func:`entry_point`): a
visit's point; a patrol line's or border piece's nearer
end; an area part's nearest boundary point. For CBBA paths of several tasks, :meth:`CostModel.path_time`
adds each task's own flight (:func:`work_length`): a visit is instantaneous, an area part is flown along
its boundary-parallel scan (its scan length at scan speed), a patrol (endless) counts one pass and ends
at its far end; patrols can only be the last task of a path (:func:`endless`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from companion.team import kinds
from companion.team.geometry import distance_m
from companion.team.types import GeoPoint, TeamTask


def endless(task: TeamTask) -> bool:
    """A patrol (line or border piece) is flown back and forth until cancelled."""
    return kinds.for_task(task.kind).endless


def entry_point(task: TeamTask, at: GeoPoint) -> GeoPoint:
    """Seed 003: "the point where the UAV will first reach" ``task`` when it comes from ``at``."""
    return kinds.for_task(task.kind).entry_point(task, at)


def exit_point(task: TeamTask, at: GeoPoint) -> GeoPoint:
    """Where the vehicle is after one pass of ``task`` entered from ``at`` (a patrol's far end)."""
    return kinds.for_task(task.kind).exit_point(task, at)


def work_length(task: TeamTask) -> float:
    """Metres flown on the task itself: 0 for a visit, the polyline for a patrol pass, the scan of an area."""
    return kinds.for_task(task.kind).work_length(task)


def euclidean(at: GeoPoint, task: TeamTask) -> float:
    """Seed 003's cost: the straight-line distance (m) to the task's characteristic point."""
    h, v = distance_m(at, entry_point(task, at))
    return math.hypot(h, v)


@dataclass(frozen=True)
class CostModel:
    """Flight time (s) under the speed, acceleration and climb-rate limits (module docstring)."""

    speed: float = 5.0
    accel: float = 2.5
    climb_speed: float = 2.5

    def __post_init__(self) -> None:
        for name in ("speed", "accel", "climb_speed"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")

    def leg_time(self, horizontal: float, vertical: float = 0.0, speed: float = 0.0) -> float:
        """Seconds to fly ``horizontal`` m from rest to rest and climb/descend ``vertical`` m, at ``speed``
        (a task's own speed, the one its tree flies: bids and flights agree) or the standard speed (0)."""
        v = speed if speed > 0 else self.speed
        d = abs(horizontal)
        if d >= v * v / self.accel:
            t = d / v + v / self.accel
        else:
            t = 2.0 * math.sqrt(d / self.accel)
        return t + abs(vertical) / self.climb_speed

    def travel_time(self, a: GeoPoint, b: GeoPoint, speed: float = 0.0) -> float:
        h, v = distance_m(a, b)
        return self.leg_time(h, v, speed)

    def cost(self, at: GeoPoint, task: TeamTask) -> float:
        """Seconds to reach ``task``'s characteristic point from ``at`` (the greedy bid)."""
        return self.travel_time(at, entry_point(task, at), task.speed)

    def work_time(self, task: TeamTask) -> float:
        """Seconds of flight on the task itself (one pass of a patrol)."""
        length = work_length(task)
        return self.leg_time(length, 0.0, task.speed) if length > 0 else 0.0

    def path_time(self, at: GeoPoint, tasks: Sequence[TeamTask]) -> float:
        """Seconds to fly ``tasks`` in order from ``at``: legs plus each task's own work (CBBA path)."""
        total = 0.0
        here = at
        for t in tasks:
            total += self.cost(here, t) + self.work_time(t)
            here = exit_point(t, here)
        return total
