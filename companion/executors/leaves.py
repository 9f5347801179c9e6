"""The platform's leaf executors (seed 000 Sec. VI, Fig. 11-14), each as the behavior it asks for.

=============================  ===============================================================  ==========
task                           behavior (seed 001) and the flight commands it queues (seed 000)  Fig.
=============================  ===============================================================  ==========
take-off                       TAKE_OFF altitude: the platform's (V_Pos, take-off flag, E_V)    11
fly-to                         GO_TO_POINT (H_Pos; V_WithHor or V_Pos by fly_straight_line_flag; 12b
                               Hd_DNU; E_H, E_V)
land                           LAND (H_DNU, V_Pos with allow landing, Hd_DNU), after a fly-to    13b
                               at the same altitude when a position is given
wait                           WAIT (all channels DNU, E_Wait)                                  VI-D
scan-ground                    FOLLOW_PATH over the expanded waypoints (H_Pos, V_WithHor, E_H,  14b
                               E_V per waypoint); the camera labels its detections with the
                               scan's data_uuid
external-velocity              FOLLOW_EXTERNAL_VELOCITY (all channels ExtVel, E_User)           VI-F
hover                          WAIT (a duration) or KEEP_HOVERING (until enough), after a        ours
                               GO_TO_POINT above ``position`` or the object bound to ``over``
request-operator-assistance    REQUEST_OPERATOR_ASSISTANCE message                              ours
=============================  ===============================================================  ==========
"""

from __future__ import annotations

from typing import Any

from companion.behaviors.activation import format_activation
from companion.behaviors.coordinator import Ended

from .base import TstExecutor, executor


def _point(p: tuple[float, float, float]) -> tuple[float, float, float]:
    return (round(p[0], 3), round(p[1], 3), round(p[2], 3))


@executor
class TakeOffExecutor(TstExecutor):
    task = "take-off"

    def activation(self) -> str:
        return format_activation("TAKE_OFF", {"altitude": self.plan.altitude_m or 2.0})


@executor
class FlyToExecutor(TstExecutor):
    task = "fly-to"

    def activation(self) -> str:
        params: dict[str, Any] = {"coordinate": _point(self.plan.position_neu or (0.0, 0.0, 2.0)),
                                  "straight_line": self.plan.straight_line}
        if self.plan.speed_m_s:
            params["speed"] = self.plan.speed_m_s
        return format_activation("GO_TO_POINT", params)


@executor
class LandExecutor(TstExecutor):
    task = "land"

    def activation(self) -> str:
        # land_at_current_position_flag: where the vehicle is when the node runs (delegation's plan only
        # estimates that place)
        if self.plan.position_neu is None or self.node.params.get("land_at_current_position_flag", True):
            return "LAND"
        return format_activation("LAND", {"coordinate": _point(self.plan.position_neu)[:2]})


@executor
class WaitExecutor(TstExecutor):
    task = "wait"

    def activation(self) -> str:
        return format_activation("WAIT", {"duration": float(self.plan.duration_s or 0.0)})


@executor
class ExternalVelocityExecutor(TstExecutor):
    task = "external-velocity"

    def activation(self) -> str:
        return "FOLLOW_EXTERNAL_VELOCITY"


@executor
class OperatorAssistanceExecutor(TstExecutor):
    task = "request-operator-assistance"

    def activation(self) -> str:
        return format_activation("REQUEST_OPERATOR_ASSISTANCE",
                                 {"message": str(self.node.params.get("message", ""))})


@executor
class HoverExecutor(TstExecutor):
    """First above the target (``position``, or the object the condition bound to ``over``), then still."""

    task = "hover"

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.phase = "go"

    def target(self) -> tuple[float, float, float] | None:
        over = self.node.params.get("over")
        if over is None:  # a given position, else where the vehicle is (the plan only estimates it)
            return self.plan.position_neu if "position" in self.node.params else None
        obj = self.ctx.bindings.get(over.lstrip("?"))
        pos = self.ctx.layer.beliefs.value("position", obj) if obj is not None else None
        if not isinstance(pos, tuple) or len(pos) < 2:
            return None
        vehicle = self.ctx.layer.ctx.vehicle()
        alt = self.plan.altitude_m or (-vehicle.p[2] if vehicle is not None else 2.0)
        return (float(pos[0]), float(pos[1]), alt)

    def activation(self) -> str:
        target = self.target()
        if target is not None and self.phase == "go":
            return format_activation("GO_TO_POINT", {"coordinate": _point(target)})
        self.phase = "stay"
        if self.plan.duration_s is not None:
            return format_activation("WAIT", {"duration": float(self.plan.duration_s)})
        return "KEEP_HOVERING"

    def on_behavior_end(self, ended: Ended) -> None:
        if self.phase == "go" and ended.cause.value == "goal_achieved":
            self.phase = "stay"
            self._ask(self.activation())
            return
        super().on_behavior_end(ended)

    def progress(self) -> dict[str, Any]:
        return {"phase": self.phase}
