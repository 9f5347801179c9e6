"""take-off (seed 000 Sec. VI-A, Fig. 11): make the platform airborne.

No input parameters: the altitude is the platform's (2 m indoor, 5 m outdoor). The executor asks for the
TAKE_OFF behavior (V_Pos, take-off flag, E_V). Fig. 4: "cannot be paused, aborted, or stopped after it
has been initiated ... all the execution information flags to false" (VI-A).
"""

from __future__ import annotations

from typing import Any

from companion.behaviors.activation import format_activation
from companion.tst.constraints import ConstraintProblem
from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.leaves.common import finish_plan, var
from companion.tst.plan import NodePlan, Vec3
from companion.tst.platform import Platform
from companion.tst.status import NodeExecutionInfo
from companion.tst.tree import TstNode


class TakeOffExecutor(TstExecutor):
    def activation(self) -> str:
        return format_activation("TAKE_OFF", {"altitude": self.plan.altitude_m or 2.0})


class TakeOff(LeafType):
    name = "take-off"
    figure = "Fig. 11"
    doc = ("Make the platform airborne; no input parameters (the altitude is the platform's: 2 m indoor, "
           "5 m outdoor).")
    info = NodeExecutionInfo(can_be_aborted=False, can_be_paused=False, can_be_enoughed=False)
    executor = TakeOffExecutor
    has_floor = False  # it starts on the ground

    def altitude_variables(self, node: TstNode, platform: Platform, problem: ConstraintProblem
                           ) -> list[tuple[str, str]]:
        alt = var(node, "altitude")
        problem.variable(alt, value=platform.takeoff_altitude,
                         label=f"{node.id}.altitude = take-off altitude {platform.takeoff_altitude:g} m")
        return [(alt, f"{node.id}.altitude")]

    def plan(self, node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3,
             speed_m_s: float | None) -> tuple[NodePlan, Vec3]:
        alt = platform.takeoff_altitude
        end = (start[0], start[1], alt)
        plan = NodePlan(str(node.id), node.type, altitude_m=alt, position_neu=end, length_m=0.0)
        return finish_plan(plan, start, platform, 0), end


TAKE_OFF = TakeOff()
