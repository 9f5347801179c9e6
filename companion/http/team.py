"""The control surface's process-monitor routes for the team (seed 003 Sec. II, Fig. 1).

Seed 003: "The Process Monitor simultaneously displays the status of individual software processes
running on each UAV, and allows the user to send high-level commands to individual processes.
Applications include commanding mode switches for a high-level controller and inflight gain tuning for
low-level controllers. If the Team Control interface fails or enters an unsafe command, it can be
overridden by sending task commands to individual aircraft through the Process Monitor."

========================================  ============================================================
``GET  /team``                            the vehicle's place in the team: status, claims, switchboard,
                                          the members it hears, the task board it holds
``POST /team/take``                       out of the team ``{"reason": "..."}`` (the team re-allocates)
``POST /team/release``                    back into the team
``POST /team/task``                       a directed task ``{"kind": "visit", "points": [[lat, lon,
                                          alt]], "altitude": 0, "speed": 0}``: taken, flies it
========================================  ============================================================

A mission given through ``POST /mission`` while the vehicle is in a team is a directed command too: the
vehicle is taken out of the team first (see :mod:`companion.http.mission`); the parameters
and the processes: :mod:`companion.http.params`.
"""

from __future__ import annotations

import itertools
from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field, field_validator

from companion.team import kinds
from companion.team.member import TeamMember
from companion.team.types import TaskKind, TeamTask
from taskflight_common.geo import check_point
from taskflight_common.httpapi import ApiError

#: ids of directed tasks (outside the station's numbering)
_directed_ids = itertools.count(1_000_000)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class TakeRequest(_Strict):
    reason: str = Field(default="process monitor", max_length=200)


class DirectedTask(_Strict):
    kind: TaskKind
    points: list[list[float]] = Field(..., min_length=1, max_length=200,
                                      description="[lat, lon] or [lat, lon, alt m above home]")
    altitude: float = Field(0.0, ge=0.0, le=1000.0)
    speed: float = Field(0.0, ge=0.0, le=50.0)

    @field_validator("points")
    @classmethod
    def _points(cls, points: list[list[float]]) -> list[list[float]]:
        for i, p in enumerate(points):
            check_point(p, f"points[{i}]")
        return points


class TeamVerb(BaseModel):
    ok: bool
    team: dict[str, Any]


def router(member: TeamMember) -> APIRouter:
    """The team routes above."""
    app = APIRouter(tags=["team"])

    @app.get("/team")
    def team() -> dict[str, Any]:
        return member.report()

    @app.post("/team/take", response_model=TeamVerb)
    def take(body: TakeRequest | None = None) -> TeamVerb:
        member.take((body or TakeRequest()).reason)
        return TeamVerb(ok=True, team=member.report())

    @app.post("/team/release", response_model=TeamVerb)
    def release() -> TeamVerb:
        member.release()
        return TeamVerb(ok=True, team=member.report())

    @app.post("/team/task", response_model=TeamVerb)
    def task(body: DirectedTask) -> TeamVerb:
        try:
            kinds.check_directed(body.kind, len(body.points))
        except ValueError as exc:
            raise ApiError(400, str(exc)) from exc
        points = tuple((p[0], p[1], p[2] if len(p) > 2 else 0.0) for p in body.points)
        t = TeamTask(next(_directed_ids), 1, body.kind, points, altitude=body.altitude, speed=body.speed,
                     name=f"directed {body.kind.value}")
        if not member.assign(t):
            errors = member.switchboard.errors
            raise ApiError(422, f"rejected: {errors[-1] if errors else 'the vehicle cannot fly it'}")
        return TeamVerb(ok=True, team=member.report())

    return app
