"""LAND (seed 001 Sec. 5.1.2): descend where the vehicle is and touch down."""

from __future__ import annotations

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

from ..controller import FlightBehavior, register


@register
class Land(FlightBehavior):
    """Situation: ``flight_state(self, flying)`` (or taking off: a landing may always cut a take-off
    short). Comes to rest, descends (allow landing; the link hands the touch-down to the autopilot's
    LAND); goal achieved once the belief memory says ``flight_state(self, landed)``."""

    behavior = "LAND"

    def situation(self, params: Mapping[str, Any]) -> str | None:
        state = self.flight_state()
        if state not in ("flying", "taking_off"):
            return f"needs flight_state(self, flying); the vehicle is {state or 'in an unknown state'}"
        if self.ctx.queue.status().queue_system_status.name == "OVERRIDDEN":
            return "the vehicle is controlled elsewhere (a pilot or ground station took it)"
        return None

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        return [FlightCommand(HorizontalChannel(HorizontalMode.DNU),
                              VerticalChannel(VerticalMode.POS, altitude=0.0, allow_landing=True),
                              HeadingChannel(HeadingMode.DNU), EndCondition(e_v=True))]

    def goal_reached(self) -> bool:
        return self.flight_state() == "landed"

    def goal_distance(self, vehicle: Any) -> float | None:
        return max(0.0, -vehicle.p[2])
