"""KEEP_HOVERING (seed 001 Sec. 5.1.2, 6.1.2): the default flight behavior: hold where the vehicle is."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from companion.flight import EndCondition, FlightCommand

from ..controller import FlightBehavior, register
from ._common import go_to, hold, need_flying, reference_neu

#: a reference this far (m, horizontally) from the measured vehicle is not where the vehicle hovers: the
#: autopilot held it elsewhere (its own fence ignores the targets beyond it, wind): hover where it is
DIVERGED_M = 5.0


@register
class KeepHovering(FlightBehavior):
    """Situation: flying. The reference comes to rest (never a jump) and holds until another flight
    behavior replaces it; it has no goal of its own (an operator's confirmation ends it). When the
    reference is more than :data:`DIVERGED_M` from the measured position (a behavior ended short of
    its goal because the autopilot's fence held the vehicle), it first brings the reference back to
    the vehicle, so that the vehicle hovers where it is and does not fly on once the fence is lifted."""

    behavior = "KEEP_HOVERING"
    measured_goal = False

    def situation(self, params: Mapping[str, Any]) -> str | None:
        return need_flying(self)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        stay = hold(EndCondition(e_user=True))
        vehicle = self.ctx.vehicle()
        if vehicle is None or self.ctx.queue.reference is None:
            return [stay]
        here = (float(vehicle.p[0]), float(vehicle.p[1]), -float(vehicle.p[2]))
        if math.dist(reference_neu(self)[:2], here[:2]) <= DIVERGED_M \
                or not self.ctx.queue.envelope.contains(vehicle.p):
            return [stay]
        return [go_to(here), stay]
