"""FOLLOW_PATH: fly through ``path`` ((north, east, up), ...) waypoints in order."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from companion.flight import FlightCommand
from companion.flight.setpoint import VehicleState

from ..controller import FlightBehavior, distance, ned_of, register
from ..services import TrajectoryPlanner
from ._common import go_to, need_flying, reference_neu


@register
class FollowPath(FlightBehavior):
    """Situation: flying. One straight leg per waypoint (planned inside the envelope; ``follow_ground``: at
    that height above the measured ground, V_GROUND); goal achieved when the last leg finished and the
    measured position is within ``goal.tolerance_m`` of the last waypoint; progress is measured toward the
    waypoint being flown; the time-out is the path's length over the speed allowed (:mod:`..timeouts`)."""

    behavior = "FOLLOW_PATH"

    def situation(self, params: Mapping[str, Any]) -> str | None:
        return need_flying(self)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        planner = self.ctx.processes.get("trajectory_planner")
        assert isinstance(planner, TrajectoryPlanner)
        legs = planner.plan(reference_neu(self), [tuple(p) for p in params["path"]])
        return [go_to(p, params.get("speed"), follow_ground=params.get("follow_ground")) for p in legs]

    def goal_distance(self, vehicle: VehicleState) -> float | None:
        path = self.params["path"]
        leg = min(len(self.finished), len(path) - 1)
        goal = ned_of(path[leg])
        if self.params.get("follow_ground") is not None:  # the height is the ground's (V_GROUND)
            return distance((vehicle.p[0], vehicle.p[1], 0.0), (goal[0], goal[1], 0.0))
        return distance(vehicle.p, goal)

    def status(self) -> dict[str, Any]:
        return {**super().status(), "waypoint": min(len(self.finished) + 1, len(self.params.get("path", ())))}
