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

from ..controller import FlightBehavior, register
from ._common import need_flying


@register
class Rotate(FlightBehavior):
    """Situation: flying; exactly one of ``angle`` / ``relative_angle``. Position held while the heading
    turns; goal achieved when the heading command finished."""

    behavior = "ROTATE"

    def situation(self, params: Mapping[str, Any]) -> str | None:
        if ("angle" in params) == ("relative_angle" in params):
            return "give exactly one of angle (a heading) or relative_angle"
        return need_flying(self)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        if "angle" in params:
            heading = HeadingChannel(HeadingMode.POS, heading=params["angle"] % 360.0)
        else:
            heading = HeadingChannel(HeadingMode.POS, heading=params["relative_angle"], frame=Frame.RELATIVE,
                                     use_sign=True, rate=math.copysign(90.0, params["relative_angle"] or 1.0))
        return [FlightCommand(HorizontalChannel(HorizontalMode.DNU), VerticalChannel(VerticalMode.DNU),
                              heading, EndCondition(e_hd=True))]
