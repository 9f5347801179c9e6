"""take-off (seed 000 Sec. VI-A, Fig. 11): make the platform airborne.

No input parameters: the altitude is the platform's (``takeoff_altitude``: 2 m indoor, 5 m outdoor);
a platform without one (``takeoff_altitude: null``) refuses the node (no made-up altitude). The
executor asks for the TAKE_OFF behavior (V_Pos, take-off flag, E_V). Fig. 4: "cannot be paused,
aborted, or stopped after it has been initiated ... all the execution information flags to false" (VI-A).
"""

from __future__ import annotations

from typing import Any

from companion.behaviors.activation import format_activation
from companion.tst.constraints import ConstraintProblem
from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.leaves.common import finish_plan, var, where
from companion.tst.plan import NodePlan, Vec3
from companion.tst.platform import Platform
from companion.tst.status import NodeExecutionInfo
from companion.tst.tree import TstNode


class TakeOffExecutor(TstExecutor):
    def activation(self) -> str:
        if not self.plan.altitude_m:  # delegation refuses it: never take off to a made-up altitude
            raise ValueError(f"node {self.node.id} (take-off): no take-off altitude")
        return format_activation("TAKE_OFF", {"altitude": self.plan.altitude_m})


class TakeOff(LeafType):
    name = "take-off"
    figure = "Fig. 11"
    doc = ("Make the platform airborne; no input parameters (the altitude is the platform's: 2 m indoor, "
           "5 m outdoor; a platform without one refuses the node).")

    info = NodeExecutionInfo(can_be_aborted=False, can_be_paused=False, can_be_enoughed=False)
    executor = TakeOffExecutor
    has_floor = False  # it starts on the ground

    def check(self, node: TstNode, platform: Platform) -> list[str]:
        out = super().check(node, platform)
        if _altitude(node, platform) is None:
            out.append(f"{where(node)}: no altitude: platform {platform.name} has no takeoff_altitude "
                       "(a take-off has no altitude parameter, Fig. 11)")
        return out

    def altitude_variables(self, node: TstNode, platform: Platform, problem: ConstraintProblem
                           ) -> list[tuple[str, str]]:
        alt = var(node, "altitude")
        value = _altitude(node, platform)
        if value is None:
            return []
        problem.variable(alt, value=value, label=f"{node.id}.altitude = take-off altitude {value:g} m")
        return [(alt, f"{node.id}.altitude")]

    def plan(self, node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3,
             speed_m_s: float | None) -> tuple[NodePlan, Vec3]:
        alt = _altitude(node, platform)
        if alt is None:
            raise ValueError("no take-off altitude")
        end = (start[0], start[1], alt)
        plan = NodePlan(str(node.id), node.type, altitude_m=alt, position_neu=end, length_m=0.0)
        return finish_plan(plan, start, platform, 0), end


def _altitude(node: TstNode, platform: Platform) -> float | None:
    """The platform's ``takeoff_altitude``; None when it has none (> 0)."""
    value = platform.takeoff_altitude
    return float(value) if value is not None and value > 0 else None


TAKE_OFF = TakeOff()
