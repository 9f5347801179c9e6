"""Visit location (seed 003 Sec. II): one point, visited once with a straight ``fly-to``."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from companion.team.types import GeoPoint, TaskKind, TeamTask

from .base import TeamTaskKind, altitude_of, speed_params

if TYPE_CHECKING:
    from companion.team.tasks import TaskDef


class Visit(TeamTaskKind):
    name = "visit"
    task_kind = TaskKind.VISIT
    wire_code = 0

    def check(self, defn: TaskDef, pts: Sequence[GeoPoint]) -> None:
        if len(pts) != 1:
            raise ValueError(f"points: a visit has exactly one point, got {len(pts)}")

    def work_length(self, task: TeamTask) -> float:
        return 0.0  # instantaneous: the vehicle is done on arrival

    def node(self, task: TeamTask, standard_altitude: float) -> dict[str, Any]:
        p = task.points[0]
        return {"type": "fly-to", "id": f"task{task.id}",
                "params": {"position": [p[0], p[1], altitude_of(task, p, standard_altitude)],
                           "fly_straight_line_flag": True, **speed_params(task)}}
