"""What each leaf of a delegated TST will fly, and ``expand()`` (seed 000 Sec. III-A, VI).

Seed 000 Sec. III-A: "Specific implementations, however, may include an expansion of the task into
subtasks. This process is invoked by calling the expand() method [...]. These are then returned and
appended to the tree". :func:`plan_leaf` computes, for one leaf whose free parameters are fixed, the
:class:`NodePlan` the executors need and the path length and time the endurance check needs;
:func:`expand` appends a leaf's children (a scan-ground's ``fly-to`` per waypoint). Both ask the leaf's
task type (:class:`~companion.tst.leaves.base.LeafType`); the time model is in
:mod:`companion.tst.leaves.common`.
"""

from __future__ import annotations

from typing import Any

from companion.tst.leaves.common import leg_time
from companion.tst.params import plan_point_to_geopoint
from companion.tst.plan import NodePlan, Vec3
from companion.tst.platform import Platform
from companion.tst.registry import leaf_type
from companion.tst.tree import TstNode

__all__ = ["NEU", "NodePlan", "expand", "leg_time", "local_to_geopoint", "plan_leaf"]

#: A plan point: (north, east, altitude above home), see :class:`NodePlan`.
NEU = Vec3


def local_to_geopoint(point: Vec3, platform: Platform) -> tuple[float, float, float]:
    """``[lat, lon, alt above home]`` of a plan point (north, east, altitude above the platform's home)."""
    return plan_point_to_geopoint(point, platform.home)


def plan_leaf(node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3,
              speed_m_s: float | None = None) -> tuple[NodePlan, Vec3]:
    """The plan of a leaf from ``start`` (a plan point), its free parameters fixed in ``values``.

    ``values`` are the node's parameters with every free one fixed (qualitative words, numbers);
    ``speed_m_s`` is the fixed speed in m/s where the task has one. Returns the plan and the position
    where the task leaves the vehicle.
    """
    return leaf_type(node.type).plan(node, platform, values, start, speed_m_s)


def expand_with_plans(node: TstNode, platform: Platform, values: dict[str, Any], plan: NodePlan,
                      speed_word: str | None = None) -> list[tuple[TstNode, NodePlan]]:
    """Sec. III-A ``expand()`` of a leaf: the children appended to ``node``, each with its plan."""
    return leaf_type(node.type).expand(node, platform, values, plan, speed_word)


def expand(node: TstNode, platform: Platform, values: dict[str, Any], plan: NodePlan | None = None,
           start: Vec3 = (0.0, 0.0, 0.0), speed_word: str | None = None) -> list[TstNode]:
    """Seed 000 Sec. III-A ``expand()``: the children a leaf appends to itself (a scan-ground's waypoints
    as ``fly-to`` children, ids ``<scan id>.wp1``, ...); most task types do not expand (an empty list).
    ``values`` are the node's parameters with the free ones fixed (see :func:`plan_leaf`).
    """
    if not node.is_leaf_task:
        return []
    if plan is None:
        plan, _ = plan_leaf(node, platform, values, start)
    return [child for child, _ in expand_with_plans(node, platform, values, plan, speed_word)]
