"""ROTATE (seed 001 Sec. 5.1.1): turn to a heading (``angle``, degrees from north) or by ``relative_angle``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from companion.flight import (
    EndCondition,
    FlightCommand,
    Frame,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    VerticalChannel,
    VerticalMode,
)
from companion.flight.setpoint import VehicleState

from ..controller import DEFAULT_TOLERANCE_DEG, FlightBehavior, register
from ._common import need_flying


@register
class Rotate(FlightBehavior):
    """Situation: flying; exactly one of ``angle`` / ``relative_angle``. Position held while the heading
    turns; goal achieved when the heading command finished and the measured heading is within the
    catalog's ``goal.tolerance_deg`` of the one asked for."""

    behavior = "ROTATE"

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.target_deg: float | None = None

    def situation(self, params: Mapping[str, Any]) -> str | None:
        if ("angle" in params) == ("relative_angle" in params):
            return "give exactly one of angle (a heading) or relative_angle"
        return need_flying(self)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        _, heading_now = self.start_point()
        if "angle" in params:
            self.target_deg = params["angle"] % 360.0
        else:
            turn = float(params["relative_angle"])
            self.target_deg = None if heading_now is None else (heading_now + turn) % 360.0
        if "angle" in params:
            heading = HeadingChannel(HeadingMode.POS, heading=params["angle"] % 360.0)
        else:
            heading = HeadingChannel(HeadingMode.POS, heading=params["relative_angle"], frame=Frame.RELATIVE,
                                     use_sign=True, rate=math.copysign(90.0, params["relative_angle"] or 1.0))
        return [FlightCommand(HorizontalChannel(HorizontalMode.DNU), VerticalChannel(VerticalMode.DNU),
                              heading, EndCondition(e_hd=True))]

    def goal_check(self, vehicle: VehicleState | None) -> str | None:
        if vehicle is None:
            return "the autopilot reports no heading"
        if self.target_deg is None:
            return None  # the heading at the start was unknown: the command's end is all there is
        error = abs(math.remainder(math.degrees(vehicle.yaw) - self.target_deg, 360.0))
        tol = self.descriptor.goal.get("tolerance_deg", DEFAULT_TOLERANCE_DEG)
        return None if error <= tol else \
            f"the heading is {error:.0f} deg from {self.target_deg:g} (tolerance {tol:g} deg)"
