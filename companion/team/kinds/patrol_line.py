"""Patrol line (seed 003 Sec. III-B, the Orbit controller): a polyline flown back and forth until
cancelled, by one vehicle."""

from __future__ import annotations

from companion.team.types import TaskKind

from .base import PatrolKind


class PatrolLine(PatrolKind):
    name = "patrol_line"
    task_kind = TaskKind.PATROL_LINE
    wire_code = 1
