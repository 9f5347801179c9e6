"""A held team task becomes a Task Specification Tree (seed 003 Sec. III-B with seed 000 Sec. III).

Seed 003: "the Waypoint controller causes each point to be visited once, whereas the Orbit controller
provides a continuous orbit of a set of points. Thus, the Waypoint controller is activated for visit
location tasks and the Orbit controller is activated for patrol tasks." Here both controllers are TSTs
flown by the vehicle's own mission layer, each kind's node built by its module of
:mod:`companion.team.kinds`:

==================  ==================================================================================
visit               ``fly-to`` the point (straight line), at the task's speed
patrol line         ``scan-ground`` along the line's waypoints in the order drawn, every leg scanned, with
                    ``repeat_flag`` (back and forth until the task is cancelled); not ``segment_flag``,
                    which reads the waypoints as separate pairs and refuses an odd count
border piece        the same patrol over that piece of the border
area part           ``scan-ground`` of the part's polygon (a lawnmower pattern, seed 000 Fig. 14)
tst                 the tree the operator gave (one child of a C node when it was divided)
==================  ==================================================================================

A vehicle on the ground takes off first (an S node with ``take-off`` then the task). Altitudes of
points are metres above home (GLOBAL_RELATIVE_ALT), as in mission files; a point without an altitude,
or with 0, is flown at the task's altitude, else at the platform's standard altitude.
"""

from __future__ import annotations

from typing import Any

from companion.tst.spec import Mission, mission_from_dict

from . import kinds
from .types import TeamTask


def task_node(task: TeamTask, standard_altitude: float) -> dict[str, Any]:
    """The TST node (a dict in the mission-file format) that flies ``task`` (its kind builds it)."""
    return kinds.for_task(task.kind).node(task, standard_altitude)


def mission_for(task: TeamTask, on_ground: bool, standard_altitude: float) -> Mission:
    """The mission a vehicle flies for ``task`` (with a take-off first when it is on the ground)."""
    node = task_node(task, standard_altitude)
    if on_ground and not _starts_with_take_off(node):
        node = {"type": "S", "id": f"team{task.id}",
                "children": [{"type": "take-off", "id": "take-off"}, node]}
    return mission_from_dict({"mission": f"team-task-{task.id}-v{task.version}",
                              "description": task.name or f"team task {task.id} ({task.kind.value})",
                              "tree": node}, file=f"<team task {task.id}>")


def _starts_with_take_off(node: dict[str, Any]) -> bool:
    while node.get("type") in ("S", "C") and node.get("children"):
        node = node["children"][0]
    return node.get("type") == "take-off"
