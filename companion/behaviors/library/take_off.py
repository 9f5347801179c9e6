"""TAKE_OFF (seed 001 Sec. 5.1.2): climb from the ground to ``altitude`` metres above home."""

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
class TakeOff(FlightBehavior):
    """Situation: ``flight_state(self, landed)``. One take-off command (the link arms, switches to
    GUIDED and sends MAV_CMD_NAV_TAKEOFF); goal achieved when it finished and the measured altitude is
    within ``goal.tolerance_m`` of ``altitude``."""

    behavior = "TAKE_OFF"

    def situation(self, params: Mapping[str, Any]) -> str | None:
        state = self.flight_state()
        if state != "landed":
            return f"needs flight_state(self, landed); the vehicle is {state or 'in an unknown state'}"
        if self.ctx.queue.status().queue_system_status.name == "OVERRIDDEN":
            return "the vehicle is controlled elsewhere (a pilot or ground station took it)"
        return None

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        return [FlightCommand(HorizontalChannel(HorizontalMode.DNU),
                              VerticalChannel(VerticalMode.POS, altitude=params["altitude"], take_off=True),
                              HeadingChannel(HeadingMode.DNU), EndCondition(e_v=True))]

    def goal_distance(self, vehicle: Any) -> float | None:
        return abs(-vehicle.p[2] - float(self.params["altitude"]))
