"""GO_TO_POINT (seed 001 Sec. 5.1.1, 6.2.1): fly to ``coordinate`` (north, east, up) metres from home."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from companion.flight import FlightCommand
from companion.flight.setpoint import VehicleState

from ..controller import FlightBehavior, distance, ned_of, register
from ..services import TrajectoryPlanner
from ._common import go_to, need_flying, reference_neu


@register
class GoToPoint(FlightBehavior):
    """Situation: flying. The trajectory planner checks the straight line inside the envelope; the
    motion controller flies it (seed 000 Fig. 12b: ``straight_line`` yes: V_WithHor, no: V_Pos; Hd_DNU;
    E_H and E_V; ``follow_ground``: V_GROUND, that height above the measured ground). Goal: the command
    finished *and* the measured position is within the catalog's ``goal.tolerance_m`` of the point
    (short of it ``goal.settle_s`` later, e.g. held by the autopilot's own fence: ``wrong_progress``).
    Performance: the time-out of its plan (distance over the speed allowed) and the progress window on
    the measured distance to the point. A point the planner cannot reach ends the behavior at its first
    check with ``wrong_progress``."""

    behavior = "GO_TO_POINT"

    def situation(self, params: Mapping[str, Any]) -> str | None:
        return need_flying(self)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        planner = self.ctx.processes.get("trajectory_planner")
        assert isinstance(planner, TrajectoryPlanner)
        legs = planner.plan(reference_neu(self), [tuple(params["coordinate"])])
        return [go_to(p, params.get("speed"), params.get("straight_line", True), params.get("follow_ground"))
                for p in legs]

    def goal_distance(self, vehicle: VehicleState) -> float | None:
        goal = ned_of(self.params["coordinate"])
        if self.params.get("follow_ground") is not None:  # the height is the ground's, not the point's
            return distance((vehicle.p[0], vehicle.p[1], 0.0), (goal[0], goal[1], 0.0))
        return distance(vehicle.p, goal)
