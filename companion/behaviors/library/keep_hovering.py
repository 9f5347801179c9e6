"""KEEP_HOVERING (seed 001 Sec. 5.1.2, 6.1.2): the default flight behavior: hold where the reference is."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from companion.flight import EndCondition, FlightCommand

from ..controller import FlightBehavior, register
from ._common import hold, need_flying


@register
class KeepHovering(FlightBehavior):
    """Situation: flying. The reference comes to rest (never a jump) and holds until another flight
    behavior replaces it; it has no goal of its own (an operator's confirmation ends it)."""

    behavior = "KEEP_HOVERING"
    measured_goal = False

    def situation(self, params: Mapping[str, Any]) -> str | None:
        return need_flying(self)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        return [hold(EndCondition(e_user=True))]
