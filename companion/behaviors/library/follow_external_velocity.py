"""FOLLOW_EXTERNAL_VELOCITY: fly the ``ext_vel`` stream of one ``source`` until the operator confirms.

``source`` (seed 000 Sec. VI-F's external-velocity; the names are :data:`companion.flight.external.SOURCES`):
``joystick`` (the default: the operator's stick, ``POST /behaviors/joystick``) or ``external`` (a program's
stream, ``POST /external/ext_vel``). While the behavior runs the queue takes ``ext_vel`` from that source
only: a sample from another one is ignored and moves nothing.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from companion.flight import FlightCommand
from companion.flight.pause_routines import joystick_command

from ..controller import FlightBehavior, register
from ._common import need_flying


@register
class FollowExternalVelocity(FlightBehavior):
    """Situation: flying. Opens the ``joystick_feed``; all channels follow its samples (seed 000's
    ExtVel, Fig. 14's external-velocity executor); goal achieved when the operator confirms
    (``user_confirm``). A silent joystick stops the vehicle (the samples' validity runs out)."""

    behavior = "FOLLOW_EXTERNAL_VELOCITY"
    measured_goal = False

    def situation(self, params: Mapping[str, Any]) -> str | None:
        return need_flying(self)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        return [joystick_command()]

    def on_start(self, params: Mapping[str, Any]) -> None:
        self.ctx.queue.select_external_source("ext_vel", str(params.get("source") or "joystick"))
        try:
            super().on_start(params)
        except BaseException:
            self.ctx.queue.select_external_source("ext_vel", None)
            raise

    def on_stop(self) -> None:
        self.ctx.queue.select_external_source("ext_vel", None)
        super().on_stop()
