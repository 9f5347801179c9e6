"""Border patrol (seed 003 Sec. II): "The border is then divided into the desired number of individual
UAV tasks": ``n`` consecutive pieces of equal length, each patrolled back and forth by one vehicle."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from companion.team.geometry import LocalFrame, split_line_equal
from companion.team.types import GeoPoint, TaskKind, TeamTask

from .base import PatrolKind, piece_name

if TYPE_CHECKING:
    from companion.team.tasks import TaskDef

#: a border piece shorter than this (m) makes no sense to patrol
MIN_PIECE_M = 10.0


class BorderPatrol(PatrolKind):
    name = "border_patrol"
    task_kind = TaskKind.BORDER_PIECE
    wire_code = 2
    divided_by_n = True

    def divide(self, defn: TaskDef, pts: tuple[GeoPoint, ...], ids: Iterator[int], group: int,
               common: dict[str, Any]) -> list[TeamTask]:
        frame = LocalFrame.around(pts)
        line = frame.line(pts)
        if line.length / defn.n < MIN_PIECE_M:
            raise ValueError(f"n: {defn.n} pieces of a {line.length:.0f} m border are shorter than "
                             f"{MIN_PIECE_M:g} m each")
        z = common["altitude"] or pts[0][2]
        return [TeamTask(id=next(ids), kind=self.task_kind, points=frame.geo_points(p.coords, z),
                         group=group, group_size=defn.n, name=piece_name(defn.name, k), **common)
                for k, p in enumerate(split_line_equal(line, defn.n))]
