"""FOLLOW_PATH: fly through ``path`` ((north, east, up), ...) waypoints in order.

``loiter_mode`` (scan-ground's, seed 000 Fig. 14a; its values are ours): ``stop`` (the default) comes to
rest at every waypoint; ``pass`` flies through them: each leg but the last ends at the waypoint with the
speed :func:`pass_speed` allows for the turn into the next leg (H_Pos's end speed, Fig. 7a), and the next
leg goes on from that speed (the reference stays continuous, Sec. IV-D).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from companion.flight import FlightCommand
from companion.flight.setpoint import VehicleState

from ..controller import FlightBehavior, distance, ned_of, register
from ..services import TrajectoryPlanner
from ._common import go_to, need_flying, reference_neu

#: the velocity across the next leg a waypoint may be flown through with, in seconds of the horizontal
#: acceleration limit (0.5 s: 1.25 m/s at 2.5 m/s²); measured on the kinematic model, more makes the next
#: leg slower than a stop would (the generator brings that velocity back onto the leg's line first)
PASS_CROSS_S = 0.5
#: from this turn on (degrees) the path turns back on itself: pass comes to rest there as stop does
PASS_MAX_TURN_DEG = 120.0


def pass_speed(before: tuple[float, ...], at: tuple[float, ...], after: tuple[float, ...],
               cruise: float, cross_budget: float) -> float:
    """The speed to fly through waypoint ``at`` from ``before`` toward ``after`` ((north, east, up) each).

    The leg ends with its velocity along itself, and the next leg first brings the part across it back onto
    its own straight line (the reference generator never cuts a corner, Sec. IV-D), so that part is held to
    ``cross_budget`` (m/s): ``min(cruise, cross_budget / sin(turn))``. A turn of :data:`PASS_MAX_TURN_DEG`
    or more, or a leg without horizontal length, stops (0)."""
    a = (at[0] - before[0], at[1] - before[1])
    b = (after[0] - at[0], after[1] - at[1])
    na, nb = math.hypot(*a), math.hypot(*b)
    if na < 1e-6 or nb < 1e-6:
        return 0.0
    cos_turn = max(-1.0, min(1.0, (a[0] * b[0] + a[1] * b[1]) / (na * nb)))
    turn = math.acos(cos_turn)
    if math.degrees(turn) >= PASS_MAX_TURN_DEG:
        return 0.0
    sin_turn = math.sin(turn)
    return cruise if sin_turn * cruise <= cross_budget else cross_budget / sin_turn


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
        start = reference_neu(self)
        legs = planner.plan(start, [tuple(p) for p in params["path"]])
        speed = params.get("speed")
        ground = params.get("follow_ground")
        if params.get("loiter_mode") != "pass":  # stop: come to rest at every waypoint
            return [go_to(p, speed, follow_ground=ground) for p in legs]
        limits = self.ctx.queue.limits
        cruise = min(speed or math.inf, limits.horizontal_speed)
        budget = PASS_CROSS_S * limits.horizontal_acceleration
        points = [start, *legs]
        return [go_to(p, speed, follow_ground=ground,
                      end_speed=pass_speed(points[i], p, points[i + 2], cruise, budget)
                      if i + 2 < len(points) else None)
                for i, p in enumerate(legs)]

    def goal_distance(self, vehicle: VehicleState) -> float | None:
        path = self.params["path"]
        leg = min(len(self.finished), len(path) - 1)
        goal = ned_of(path[leg])
        if self.params.get("follow_ground") is not None:  # the height is the ground's (V_GROUND)
            return distance((vehicle.p[0], vehicle.p[1], 0.0), (goal[0], goal[1], 0.0))
        return distance(vehicle.p, goal)

    def status(self) -> dict[str, Any]:
        return {**super().status(), "waypoint": min(len(self.finished) + 1, len(self.params.get("path", ())))}
