"""A leaf task type defined here, registered, delegated and flown (seed 000 Sec. III-A, Fig. 3-5).

``circle-point`` is not one of the platform's task types: this module gives all of it, its parameters,
its ``check()`` and ``get_constraints()``, its plan and its executor, registers it
(:func:`companion.tst.registry.register`), and nothing else of the project changes. A mission using it is
loaded from YAML, delegated to the indoor platform (which then says it has the executor), its free
radius fixed by the constraint solver, and flown by the TST execution system over the behaviors layer
with the kinematic vehicle of :mod:`behaviors_support`. The vehicle must really circle the centre at the
radius the solver chose.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest

from companion.behaviors.activation import format_activation
from companion.tst.constraints import ConstraintProblem
from companion.tst.delegation import delegate
from companion.tst.execution import TstExecutionSystem
from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.leaves.common import declare_number, finish_plan, var, where
from companion.tst.param_spec import ParamSpec
from companion.tst.params import ParamError, plan_point, plan_point_to_geopoint
from companion.tst.plan import NodePlan, Vec3
from companion.tst.platform import Platform, bundled_platform
from companion.tst.registry import leaf_type, register, unregister
from companion.tst.spec import mission_from_yaml
from companion.tst.status import NodeExecutionInfo
from companion.tst.tree import TstNode
from harness.behaviors import World


class CirclePointExecutor(TstExecutor):
    """Flies the planned circle as one FOLLOW_PATH (so it can be paused and enoughed as one task)."""

    def activation(self) -> str:
        path = tuple(tuple(round(c, 3) for c in w) for w in self.plan.waypoints_neu)
        params: dict[str, Any] = {"path": path}
        if self.plan.speed_m_s:
            params["speed"] = self.plan.speed_m_s
        return format_activation("FOLLOW_PATH", params)


class CirclePoint(LeafType):
    """Circle a point once at a given (or constrained) radius, at the centre's altitude."""

    name = "circle-point"
    figure = "ours (test)"
    doc = "Fly once around a point at a radius."
    params = (
        ParamSpec("center", "geopoint", "The point circled, [lat, lon, alt above home].", required=True),
        ParamSpec("radius", "float", "The circle's radius.", required=True, unit="m", minimum=0.5),
        ParamSpec("points", "float", "Waypoints on the circle.", default=12.0, minimum=4.0),
    )
    info = NodeExecutionInfo(can_be_aborted=True, can_be_paused=True, can_be_enoughed=True)
    executor = CirclePointExecutor
    has_speed = True  # the solver picks a qualitative speed

    def check_params(self, p: dict[str, Any]) -> None:
        if p["points"] != int(p["points"]):
            raise ParamError("a whole number of waypoints", "points")

    def check(self, node: TstNode, platform: Platform) -> list[str]:
        out = super().check(node, platform)
        radius = node.params["radius"]
        if isinstance(radius, float):  # a free radius is checked once the solver fixed it (in plan)
            n, e, _ = plan_point(node.params["center"], platform.home)
            for k in range(8):
                a = 2 * math.pi * k / 8
                why = platform.fence_reason((n + radius * math.cos(a), e + radius * math.sin(a)))
                if why:
                    out.append(f"{where(node)}: circle outside the fence: {why}")
                    break
        return out

    def get_constraints(self, node: TstNode, platform: Platform, problem: ConstraintProblem,
                        plan: NodePlan | None = None, fixed: Any = None) -> None:
        super().get_constraints(node, platform, problem, plan, fixed)
        if plan is None:
            declare_number(problem, var(node, "radius"), node.params["radius"], f"{node.id}.radius", lo=0.5)

    def plan(self, node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3,
             speed_m_s: float | None) -> tuple[NodePlan, Vec3]:
        cn, ce, alt = plan_point(values["center"], platform.home)
        r, k = float(values["radius"]), int(values["points"])
        wps = [(cn + r * math.cos(2 * math.pi * i / k), ce + r * math.sin(2 * math.pi * i / k), alt)
               for i in range(k + 1)]
        plan = NodePlan(str(node.id), node.type, speed_m_s=speed_m_s, altitude_m=alt, waypoints_neu=wps,
                        length_m=math.dist(start[:2], wps[0][:2]) + 2 * math.pi * r)
        plan.extra.update({"center_ne": [cn, ce], "radius_m": r})
        return finish_plan(plan, start, platform, k + 1), wps[-1]


INDOOR = bundled_platform("indoor")
CENTER = (4.0, 3.0, 2.5)  # north, east, altitude above home


@pytest.fixture
def circle_point() -> Iterator[CirclePoint]:
    leaf = register(CirclePoint())
    try:
        yield leaf
    finally:
        unregister(leaf.name)


def mission_text(radius: str) -> str:
    lat, lon, alt = plan_point_to_geopoint(CENTER, INDOOR.home)
    return f"""
mission: circle
tree:
  type: S
  children:
    - {{type: take-off, id: up}}
    - {{type: circle-point, id: circle, params: {{center: [{lat}, {lon}, {alt}], radius: {radius}}}}}
    - {{type: land, id: down}}
"""


def test_a_leaf_type_defined_in_a_test_is_delegated_and_flown(circle_point: CirclePoint) -> None:
    assert leaf_type("circle-point") is circle_point
    platform = INDOOR.with_tasks((*INDOOR.tasks, "circle-point"))
    mission = mission_from_yaml(mission_text("{interval: [1.0, 2.0]}"), "circle.yaml")
    result = delegate(mission, platform)
    assert result.accepted, result.reasons
    assert result.fixed["circle.radius"] == pytest.approx(1.5)  # the solver's middle of the interval
    plan = result.plans["circle"]
    assert plan.speed_m_s == platform.speeds["standard"] and plan.expected_s and plan.expected_s > 9.0

    world = World()
    system = TstExecutionSystem(world.layer)
    world.layer.cycle_listeners.append(system.tick)
    system.load(result.mission, result.plans)
    system.start()
    world.run_until(lambda: system.active_node() == "circle", 40, "the circle")
    samples: list[tuple[float, float, float]] = []
    world.run_until(lambda: (samples.append(world.pos_neu) or system.active_node() != "circle"), 60,
                    "the circle's end")
    world.run_until(lambda: not system.running, 40, "the landing")
    assert system.status()["state"] == "succeeded", system.status()

    start = plan.waypoints_neu[0]  # the circle begins once the vehicle reached its first waypoint
    first = next(i for i, s in enumerate(samples) if math.dist(s, start) < 0.2)
    flown = samples[first:]
    radii = [math.dist(s[:2], CENTER[:2]) for s in flown]
    assert min(radii) > 1.5 - 0.3 and max(radii) < 1.5 + 0.3, (min(radii), max(radii))
    assert all(abs(s[2] - CENTER[2]) < 0.3 for s in flown)
    bearings = {int((math.degrees(math.atan2(s[1] - CENTER[1], s[0] - CENTER[0])) % 360) // 30)
                for s in flown}
    assert len(bearings) == 12  # every 30-degree sector of the circle was flown through


def test_the_new_type_checks_and_constrains_through_delegation(circle_point: CirclePoint) -> None:
    platform = INDOOR.with_tasks((*INDOOR.tasks, "circle-point"))
    too_big = delegate(mission_from_yaml(mission_text("30.0"), "big.yaml"), platform)
    assert not too_big.accepted
    assert any("circle outside the fence" in r for r in too_big.reasons), too_big.reasons
    without = delegate(mission_from_yaml(mission_text("1.0"), "m.yaml"), INDOOR)
    assert not without.accepted and "unknown task" in without.reasons[0]
    with pytest.raises(ValueError, match="points: a whole number"):
        mission_from_yaml(mission_text("1.0").replace("radius: 1.0", "radius: 1.0, points: 6.5"), "p.yaml")
