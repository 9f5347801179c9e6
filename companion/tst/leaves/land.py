"""land (seed 000 Sec. VI-C, Fig. 13): land at the current or a specified location.

The executor asks for LAND (H_DNU, V_Pos with allow landing, Hd_DNU), flying first to the given position
at the same altitude. Fig. 4 (ours, VI-C is silent): a landing may be aborted (a go-around, an urgent
stop); pausing a descent is not offered; a landing has an end of its own, so no enough.
"""

from __future__ import annotations

import math
from typing import Any

from companion.behaviors.activation import format_activation
from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.leaves.common import finish_plan, point_reasons, where
from companion.tst.leaves.fly_to import rounded
from companion.tst.param_spec import ParamSpec
from companion.tst.params import ParamError, plan_point
from companion.tst.plan import NodePlan, Vec3
from companion.tst.platform import Platform
from companion.tst.status import NodeExecutionInfo
from companion.tst.tree import TstNode


class LandExecutor(TstExecutor):
    def activation(self) -> str:
        # land_at_current_position_flag: where the vehicle is when the node runs (delegation's plan only
        # estimates that place)
        if self.plan.position_neu is None or self.node.params.get("land_at_current_position_flag", True):
            return "LAND"
        return format_activation("LAND", {"coordinate": rounded(self.plan.position_neu)[:2]})


class Land(LeafType):
    name = "land"
    figure = "Fig. 13a"
    doc = "Land at the current or a specified location."
    params = (
        ParamSpec("position", "geopoint", "Geographical location of the landing."),
        ParamSpec("land_at_current_position_flag", "bool",
                  "Use position or current location (ours: defaults to true exactly when no position "
                  "is given)."),
    )
    info = NodeExecutionInfo(can_be_aborted=True, can_be_paused=False, can_be_enoughed=False)
    executor = LandExecutor

    def check_params(self, p: dict[str, Any]) -> None:
        flag = p.get("land_at_current_position_flag")
        if flag is None:
            p["land_at_current_position_flag"] = "position" not in p
        elif flag is False and "position" not in p:
            raise ParamError("required when land_at_current_position_flag is false", "position")
        elif flag is True and "position" in p:
            raise ParamError("given, but land_at_current_position_flag is true", "position")

    def check(self, node: TstNode, platform: Platform) -> list[str]:
        out = super().check(node, platform)
        p = node.params
        if "position" in p and not p.get("land_at_current_position_flag"):
            out += point_reasons(where(node), "position", p["position"], platform, altitude=False)
        return out

    def plan(self, node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3,
             speed_m_s: float | None) -> tuple[NodePlan, Vec3]:
        if values.get("land_at_current_position_flag", True) or "position" not in values:
            target = (start[0], start[1], 0.0)
        else:
            n, e, _ = plan_point(values["position"], platform.home)
            target = (n, e, 0.0)
        length = math.dist(start[:2], target[:2])
        standard = platform.speeds.get("standard", 1.0)
        plan = NodePlan(str(node.id), node.type, speed_m_s=standard if length > 0 else None, altitude_m=0.0,
                        position_neu=target, length_m=length)
        plan.extra["land_at_current_position"] = bool(values.get("land_at_current_position_flag", True))
        return finish_plan(plan, start, platform, 1 if length > 0 else 0), target


LAND = Land()
