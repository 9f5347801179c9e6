"""wait (seed 000 Sec. VI-D): a timed period of inactivity (all channels DNU, E_Wait).

The duration's name (``duration``, s) is ours: Sec. VI-D only says "the amount of time to wait". The
executor asks for the WAIT behavior. Fig. 4 (ours, VI-D is silent): a wait may be cut short (enough) or
aborted; pausing a pause means nothing.
"""

from __future__ import annotations

import math
from typing import Any

from companion.behaviors.activation import format_activation
from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.leaves.common import finish_plan
from companion.tst.param_spec import ParamSpec
from companion.tst.params import plan_point
from companion.tst.plan import NodePlan, Vec3
from companion.tst.platform import Platform
from companion.tst.status import NodeExecutionInfo
from companion.tst.tree import TstNode


def stay_plan(node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3
              ) -> tuple[NodePlan, Vec3]:
    """Stay ``duration`` s (absent: until enough) at ``position`` (absent: where the vehicle is)."""
    duration = values.get("duration")
    target = plan_point(values["position"], platform.home) if "position" in values else start
    length = math.dist(start[:2], target[:2])
    standard = platform.speeds.get("standard", 1.0)
    plan = NodePlan(str(node.id), node.type, speed_m_s=standard if length > 0 else None, altitude_m=target[2],
                    position_neu=target, length_m=length, duration_s=duration)
    if duration is None:
        plan.extra["until"] = "enough"
    return finish_plan(plan, start, platform, 1 if length > 0 else 0, duration or 0.0), target


class WaitExecutor(TstExecutor):
    def activation(self) -> str:
        return format_activation("WAIT", {"duration": float(self.plan.duration_s or 0.0)})


class Wait(LeafType):
    name = "wait"
    figure = "Sec. VI-D"
    doc = "A timed period of inactivity (all channels DNU, E_Wait)."
    params = (ParamSpec("duration", "float", "The amount of time to wait (the name is ours).", required=True,
                        unit="s", minimum=0.0),)
    info = NodeExecutionInfo(can_be_aborted=True, can_be_paused=False, can_be_enoughed=True)
    executor = WaitExecutor
    flies = False  # all channels DNU

    def plan(self, node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3,
             speed_m_s: float | None) -> tuple[NodePlan, Vec3]:
        return stay_plan(node, platform, values, start)


WAIT = Wait()
