"""Area scan: a polygon cut into ``n`` parts of equal area (:func:`~companion.team.geometry.
split_polygon_equal_area`), each scanned by one vehicle with ``scan-ground`` (a lawnmower pattern,
seed 000 Fig. 14)."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, Any

from shapely.geometry import Point
from shapely.ops import nearest_points

from companion.team.geometry import LocalFrame, split_polygon_equal_area
from companion.team.types import GeoPoint, TaskKind, TeamTask

from .base import Route, TeamTaskKind, altitude_params, piece_name, speed_params, with_altitude

if TYPE_CHECKING:
    from companion.team.tasks import TaskDef

#: an area part smaller than this (m^2) makes no sense to scan
MIN_PART_M2 = 100.0
#: spacing (m) of the scan lines of an area part (its flight length = area / spacing + perimeter)
SCAN_SPACING_M = 10.0


class AreaScan(TeamTaskKind):
    name = "area_scan"
    task_kind = TaskKind.AREA_PART
    wire_code = 3
    divided_by_n = True
    min_points = 3

    def check(self, defn: TaskDef, pts: Sequence[GeoPoint]) -> None:
        if len(pts) < 3:
            raise ValueError(f"points: an area needs at least 3 points, got {len(pts)}")
        poly = LocalFrame.around(pts).polygon(pts)
        if poly.area <= 1e-9:
            raise ValueError("points: the area polygon has zero area")
        if not poly.is_valid or not poly.exterior.is_simple:
            raise ValueError("points: the area polygon is not simple (its edges cross)")

    def divide(self, defn: TaskDef, pts: tuple[GeoPoint, ...], ids: Iterator[int], group: int,
               common: dict[str, Any]) -> list[TeamTask]:
        frame = LocalFrame.around(pts)
        poly = frame.polygon(pts)
        if poly.area / defn.n < MIN_PART_M2:
            raise ValueError(f"n: {defn.n} parts of a {poly.area:.0f} m^2 area are smaller than "
                             f"{MIN_PART_M2:g} m^2 each")
        z = common["altitude"] or pts[0][2]
        return [TeamTask(id=next(ids), kind=self.task_kind,
                         points=frame.geo_points(list(p.exterior.coords)[:-1], z),
                         group=group, group_size=defn.n, name=piece_name(defn.name, k), **common)
                for k, p in enumerate(split_polygon_equal_area(poly, defn.n))]

    def entry_point(self, task: TeamTask, at: GeoPoint) -> GeoPoint:
        """The nearest point of the part's boundary (here, when inside it)."""
        pts = task.points
        if len(pts) < 3:
            return super().entry_point(task, at)
        frame = LocalFrame(at[0], at[1])
        poly = frame.polygon(pts)
        here = Point(0.0, 0.0)
        if poly.contains(here):
            return with_altitude(task, (at[0], at[1], pts[0][2]))
        q = nearest_points(poly.exterior, here)[0]
        return with_altitude(task, frame.to_geo(q.x, q.y, pts[0][2]))

    def work_length(self, task: TeamTask) -> float:
        """The boundary-parallel scan: area / spacing + perimeter."""
        pts = task.points
        if len(pts) < 3:
            return super().work_length(task)
        poly = LocalFrame.around(pts).polygon(pts)
        return poly.area / SCAN_SPACING_M + poly.exterior.length

    def route(self, task: TeamTask, at: GeoPoint) -> Route:
        ring = [with_altitude(task, p) for p in task.points]
        return Route([self.entry_point(task, at)], loop=[*ring, ring[0]], scan_m=self.work_length(task))

    def node(self, task: TeamTask, standard_altitude: float) -> dict[str, Any]:
        return {"type": "scan-ground", "id": f"task{task.id}",
                "params": {"area": [[p[0], p[1]] for p in task.points], **speed_params(task),
                           **altitude_params(task), "data_uuid": f"team-task-{task.id}"}}
