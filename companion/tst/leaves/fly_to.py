"""fly-to (seed 000 Sec. VI-B, Fig. 12): bring the platform to a specified location.

Parameters as Fig. 12a; its ``commanded-speed`` is written ``commanded_speed`` (the hyphenated form is
accepted). The executor asks for GO_TO_POINT (H_Pos; V_WithHor or V_Pos by fly_straight_line_flag;
Hd_DNU; E_H, E_V). Fig. 4: "can be paused and aborted" (VI-B), not enoughed.
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import Any

from companion.behaviors.activation import format_activation
from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.leaves.common import (
    check_follow_ground,
    finish_plan,
    follow_ground_params,
    point_reasons,
    where,
)
from companion.tst.param_spec import ParamSpec
from companion.tst.params import ParamError, plan_point
from companion.tst.plan import NodePlan, Vec3
from companion.tst.platform import Platform
from companion.tst.status import NodeExecutionInfo
from companion.tst.tree import TstNode


def rounded(p: tuple[float, float, float]) -> tuple[float, float, float]:
    """A plan point as a behavior coordinate (millimetres)."""
    return (round(p[0], 3), round(p[1], 3), round(p[2], 3))


class FlyToExecutor(TstExecutor):
    def activation(self) -> str:
        if self.plan.position_neu is None:  # delegation refuses it: never fly a made-up point
            raise ValueError(f"node {self.node.id} (fly-to): no position to fly to")
        params: dict[str, Any] = {"coordinate": rounded(self.plan.position_neu),
                                  "straight_line": self.plan.straight_line}
        if self.plan.speed_m_s:
            params["speed"] = self.plan.speed_m_s
        if self.plan.extra.get("follow_ground_altitude") is not None:  # flown above the measured ground
            params["follow_ground"] = float(self.plan.extra["follow_ground_altitude"])
        return format_activation("GO_TO_POINT", params)


class FlyTo(LeafType):
    name = "fly-to"
    figure = "Fig. 12a"
    doc = "Bring the platform to a specified location."
    params = (
        ParamSpec("position", "geopoint", "Geographical location of the target position.", required=True),
        ParamSpec("commanded_speed", "float", "Wanted speed in m/s.", unit="m/s", minimum=0.0),
        ParamSpec("speed", "qualitative", 'Qualitative specification: "slow", "standard", "fast".',
                  options=("slow", "standard", "fast")),
        *follow_ground_params(),
        ParamSpec("fly_straight_line_flag", "bool", "Enforce straight line flight to the target position.",
                  default=False),
    )
    aliases = MappingProxyType({"commanded-speed": "commanded_speed"})
    info = NodeExecutionInfo(can_be_aborted=True, can_be_paused=True, can_be_enoughed=False)
    executor = FlyToExecutor
    has_speed = True

    def check_params(self, p: dict[str, Any]) -> None:
        if "speed" in p and "commanded_speed" in p:
            raise ParamError("give speed or commanded_speed, not both (Fig. 12a: two ways)",
                             "commanded_speed")
        check_follow_ground(p)

    def check(self, node: TstNode, platform: Platform) -> list[str]:
        if node.params.get("position") is None:
            return [*super().check(node, platform),
                    f"{where(node)}: no position: a fly-to needs the position to fly to (Fig. 12a)"]
        return [*super().check(node, platform),
                *point_reasons(where(node), "position", node.params["position"], platform, altitude=True)]

    def plan(self, node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3,
             speed_m_s: float | None) -> tuple[NodePlan, Vec3]:
        target = plan_point(values["position"], platform.home)
        plan = NodePlan(str(node.id), node.type, speed_m_s=speed_m_s, altitude_m=target[2],
                        position_neu=target, straight_line=bool(values.get("fly_straight_line_flag", False)),
                        length_m=math.dist(start[:2], target[:2]))
        if values.get("follow_ground_flag"):
            plan.extra["follow_ground_altitude"] = values.get("follow_ground_altitude")
        if "speed" in values:
            plan.extra["speed"] = values["speed"]
        return finish_plan(plan, start, platform, 1), target


FLY_TO = FlyTo()
