"""LAND (seed 001 Sec. 5.1.2): descend where the vehicle is and touch down."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from companion.flight import (
    EndCondition,
    FlightCommand,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    VerticalChannel,
    VerticalMode,
)
from companion.flight.setpoint import VehicleState

from ..controller import DEFAULT_TOLERANCE_M, FlightBehavior, register
from ..services import TrajectoryPlanner
from ._common import go_to, need_flying, reference_neu


@register
class Land(FlightBehavior):
    """Situation: ``flight_state(self, flying)`` (or taking off: a landing may always cut a take-off
    short). Seed 000 Fig. 13b: where it is (H_DNU, V_Pos to the ground with allow landing, Hd_DNU; the
    link hands the touch-down to the autopilot's LAND), or, with ``coordinate`` (north, east), first
    a fly-to there at the current altitude. Goal achieved once the belief memory says
    ``flight_state(self, landed)`` and, with a ``coordinate``, the measured position is within
    ``goal.tolerance_m`` of it horizontally."""

    behavior = "LAND"

    def situation(self, params: Mapping[str, Any]) -> str | None:
        return need_flying(self, or_taking_off=True)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        land = FlightCommand(HorizontalChannel(HorizontalMode.DNU),
                             VerticalChannel(VerticalMode.POS, altitude=0.0, allow_landing=True),
                             HeadingChannel(HeadingMode.DNU), EndCondition(e_v=True))
        if "coordinate" not in params:
            return [land]
        here = reference_neu(self)  # seed 000 Fig. 13b: first fly there (at the current altitude)
        target = (float(params["coordinate"][0]), float(params["coordinate"][1]), here[2])
        planner = self.ctx.processes.get("trajectory_planner")
        assert isinstance(planner, TrajectoryPlanner)
        return [go_to(p) for p in planner.plan(here, [target])] + [land]

    def goal_reached(self) -> bool:
        return self.flight_state() == "landed"

    def goal_distance(self, vehicle: Any) -> float | None:
        return max(0.0, -vehicle.p[2])

    def goal_check(self, vehicle: VehicleState | None) -> str | None:
        if "coordinate" not in self.params:
            return None  # landed where it is: the belief says so (goal_reached)
        if vehicle is None:
            return "the autopilot reports no position"
        n, e = (float(c) for c in self.params["coordinate"])
        d = math.hypot(vehicle.p[0] - n, vehicle.p[1] - e)
        tol = self.descriptor.goal.get("tolerance_m", DEFAULT_TOLERANCE_M)
        return None if d <= tol else f"it landed {d:.1f} m from ({n:g}, {e:g}) (tolerance {tol:g} m)"
