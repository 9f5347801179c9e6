"""hover (ours, for the behaviors layer): stay in place for a duration, or until enough is requested.

Not in seed 000: it serves the WHILE/IF mission of "scan until a person is seen, then hover over it and
ask the operator". The executor flies first above the target (``position``, or the object the enclosing
IF / WHILE condition bound to ``over``) with GO_TO_POINT, then asks for WAIT (a duration) or
KEEP_HOVERING (until enough). Fig. 4 (ours): like wait.
"""

from __future__ import annotations

from typing import Any

from companion.behaviors.activation import format_activation
from companion.behaviors.coordinator import Ended
from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.leaves.common import point_reasons, where
from companion.tst.leaves.fly_to import rounded
from companion.tst.leaves.wait import stay_plan
from companion.tst.param_spec import ParamSpec
from companion.tst.params import ParamError
from companion.tst.plan import NodePlan, Vec3
from companion.tst.platform import Platform
from companion.tst.status import NodeExecutionInfo
from companion.tst.tree import TstNode


class HoverExecutor(TstExecutor):
    """First above the target (``position``, or the object the condition bound to ``over``), then still."""

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
            return format_activation("GO_TO_POINT", {"coordinate": rounded(target)})
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


class Hover(LeafType):
    name = "hover"
    figure = "ours (behaviors layer)"
    doc = "Stay in place for a duration, or until enough is requested."
    params = (
        ParamSpec("duration", "float", "Seconds to stay; absent: until enough.", unit="s", minimum=0.0),
        ParamSpec("position", "geopoint", "Where to hover; absent: where the platform is."),
        ParamSpec("over", "string", "Hover above the object bound to this variable by the enclosing IF or "
                  "WHILE condition (e.g. ?x, with position(?x, ...) in the beliefs; ours)."),
    )
    info = NodeExecutionInfo(can_be_aborted=True, can_be_paused=False, can_be_enoughed=True)
    executor = HoverExecutor

    def check_params(self, p: dict[str, Any]) -> None:
        over = p.get("over")
        variable = isinstance(over, str) and over.startswith("?") and over[1:].isidentifier()
        if over is not None and not variable:
            raise ParamError("expected a condition's variable such as ?x", "over")
        if over is not None and "position" in p:
            raise ParamError("give position or over, not both", "over")

    def check(self, node: TstNode, platform: Platform) -> list[str]:
        out = super().check(node, platform)
        if "position" in node.params:
            out += point_reasons(where(node), "position", node.params["position"], platform, altitude=True)
        return out

    def plan(self, node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3,
             speed_m_s: float | None) -> tuple[NodePlan, Vec3]:
        return stay_plan(node, platform, values, start)


HOVER = Hover()
