"""What every team task kind provides, and the defaults most kinds share (seed 003 Sec. II-III).

A kind is one module of :mod:`companion.team.kinds` with one :class:`TeamTaskKind` subclass: how the
operator's definition is checked and divided among vehicles, the point a vehicle first reaches and the
metres it flies on the task (its cost), the route a kinematic stand-in flies, and the Task Specification
Tree node that flies it on a real vehicle (seed 000 Sec. III).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from companion.team.geometry import LocalFrame, distance_m
from companion.team.types import GeoPoint, TaskKind, TeamTask

if TYPE_CHECKING:
    from companion.team.tasks import TaskDef

#: speed name of a task without a speed of its own
DEFAULT_SPEED = "standard"


@dataclass(frozen=True)
class Route:
    """What a kinematic stand-in flies for a task: ``waypoints`` once, then ``loop`` (a patrol's points
    back and forth, or an area's ring round and round while ``scan_m`` metres are left to scan)."""

    waypoints: list[GeoPoint]
    loop: list[GeoPoint] | None = None
    scan_m: float = 0.0


def check_point(p: Any, where: str) -> GeoPoint:
    """A [lat, lon] or [lat, lon, alt] of finite numbers in range (ValueError naming ``where``)."""
    if not isinstance(p, list | tuple) or len(p) not in (2, 3):
        raise ValueError(f"{where}: expected [lat, lon] or [lat, lon, alt], got {p!r}")
    vals = []
    for v in p:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ValueError(f"{where}: expected finite numbers, got {p!r}")
        vals.append(float(v))
    if not (-90.0 <= vals[0] <= 90.0 and -180.0 <= vals[1] <= 180.0):
        raise ValueError(f"{where}: latitude/longitude out of range: {p!r}")
    return (vals[0], vals[1], vals[2] if len(vals) == 3 else 0.0)


def with_altitude(task: TeamTask, p: GeoPoint) -> GeoPoint:
    """``p`` at the task's altitude when it has one."""
    return (p[0], p[1], task.altitude if task.altitude else p[2])


def altitude_of(task: TeamTask, point: GeoPoint, fallback: float) -> float:
    """A tree's altitude for ``point``: its own if above 0, else the task's, else ``fallback``."""
    if len(point) > 2 and point[2] > 0:
        return float(point[2])
    return task.altitude if task.altitude > 0 else fallback


def speed_params(task: TeamTask) -> dict[str, Any]:
    """The tree's speed: the task's own (m/s, flown and bid with) or the platform's standard."""
    return {"commanded_speed": float(task.speed)} if task.speed > 0 else {"speed": DEFAULT_SPEED}


def altitude_params(task: TeamTask) -> dict[str, Any]:
    """A scan's altitude: the task's own (m above home) or the platform's standard."""
    return {"commanded_altitude": float(task.altitude)} if task.altitude > 0 else {"altitude": "standard"}


def piece_name(name: str, k: int) -> str:
    return f"{name}#{k + 1}" if name else ""


class TeamTaskKind(ABC):
    """One team task kind. Subclasses set the class attributes, give :meth:`node`, override what differs."""

    #: the operator's name of the kind (``TaskDef.kind``, task files, the ground service's API)
    name: ClassVar[str]
    #: the kind of the allocatable tasks it is divided into (on the board and the wire)
    task_kind: ClassVar[TaskKind]
    #: its code in the team wire format (:mod:`companion.team.wire`)
    wire_code: ClassVar[int]
    #: the operator gives ``n``, the task is cut into ``n`` pieces (seed 003 Sec. II)
    divided_by_n: ClassVar[bool] = False
    #: flown back and forth until cancelled (only the last task of a CBBA path)
    endless: ClassVar[bool] = False
    #: the fewest points a task of this kind has
    min_points: ClassVar[int] = 1
    #: may be given to one vehicle as a directed task (seed 003 Fig. 1, the process monitor's tier)
    directable: ClassVar[bool] = True

    # --- the operator's definition ------------------------------------------------------------------
    def points(self, defn: TaskDef) -> tuple[GeoPoint, ...]:
        """The definition's points, checked (ValueError naming the field)."""
        return tuple(check_point(p, f"points[{i}]") for i, p in enumerate(defn.points))

    def check(self, defn: TaskDef, pts: Sequence[GeoPoint]) -> None:
        """Kind-specific checks of a definition with points ``pts``."""
        if len(pts) < self.min_points:
            raise ValueError(f"points: a {defn.kind} needs at least {self.min_points} points, got {len(pts)}")

    def is_group(self, defn: TaskDef) -> bool:
        """The definition is divided into pieces under a group id (the ledger keeps its definition)."""
        return self.divided_by_n

    def divide(self, defn: TaskDef, pts: tuple[GeoPoint, ...], ids: Iterator[int], group: int,
               common: dict[str, Any]) -> list[TeamTask]:
        """The allocatable tasks of a checked definition (default: one task with its points)."""
        return [TeamTask(id=next(ids), kind=self.task_kind, points=pts, name=defn.name, **common)]

    # --- the cost (seed 003 Sec. III-B) -------------------------------------------------------------
    def task_points(self, task: TeamTask) -> Sequence[GeoPoint]:
        return task.points

    def entry_point(self, task: TeamTask, at: GeoPoint) -> GeoPoint:
        """Seed 003: "the point where the UAV will first reach" ``task`` when it comes from ``at``."""
        pts = self.task_points(task)
        return with_altitude(task, pts[0]) if pts else at

    def exit_point(self, task: TeamTask, at: GeoPoint) -> GeoPoint:
        """Where the vehicle is after one pass of ``task`` entered from ``at``."""
        return self.entry_point(task, at)

    def work_length(self, task: TeamTask) -> float:
        """Metres flown on the task itself (one pass of a patrol)."""
        pts = self.task_points(task)
        if len(pts) < 2:
            return 0.0
        return LocalFrame.around(pts).line(pts).length

    # --- the flight ---------------------------------------------------------------------------------
    def route(self, task: TeamTask, at: GeoPoint) -> Route:
        """What the team simulator's kinematic vehicle flies (default: to the entry point, done there)."""
        return Route([self.entry_point(task, at)])

    @abstractmethod
    def node(self, task: TeamTask, standard_altitude: float) -> dict[str, Any]:
        """The TST node (a dict in the mission-file format) that flies ``task``."""


class PatrolKind(TeamTaskKind):
    """A polyline flown back and forth until cancelled (a patrol line, a border piece)."""

    endless = True
    min_points = 2

    def entry_point(self, task: TeamTask, at: GeoPoint) -> GeoPoint:
        pts = self.task_points(task)
        if len(pts) < 2:
            return super().entry_point(task, at)
        a, b = pts[0], pts[-1]
        return with_altitude(task, a if distance_m(at, a)[0] <= distance_m(at, b)[0] else b)

    def exit_point(self, task: TeamTask, at: GeoPoint) -> GeoPoint:
        pts = self.task_points(task)
        start = self.entry_point(task, at)
        if len(pts) < 2:
            return start
        a, b = with_altitude(task, pts[0]), with_altitude(task, pts[-1])
        return b if distance_m(start, a)[0] <= distance_m(start, b)[0] else a

    def route(self, task: TeamTask, at: GeoPoint) -> Route:
        entry = self.entry_point(task, at)
        pts = [with_altitude(task, p) for p in task.points]
        if math.hypot(*distance_m(entry, pts[-1])) < math.hypot(*distance_m(entry, pts[0])):
            pts.reverse()
        return Route([entry], loop=pts)

    def node(self, task: TeamTask, standard_altitude: float) -> dict[str, Any]:
        """``scan-ground`` along the waypoints in the order drawn, every leg scanned, with ``repeat_flag``
        (back and forth until cancelled); not ``segment_flag``, which reads the waypoints as separate
        pairs and refuses an odd count."""
        wps = [[p[0], p[1], altitude_of(task, p, standard_altitude)] for p in task.points]
        return {"type": "scan-ground", "id": f"task{task.id}",
                "params": {"waypoints_scan_flag": True, "waypoints": wps, "segment_flag": False,
                           "repeat_flag": True, "loiter_mode": "pass", **speed_params(task),
                           "data_uuid": f"team-task-{task.id}"}}
