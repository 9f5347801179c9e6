"""A held team task becomes a Task Specification Tree (seed 003 Sec. III-B with seed 000 Sec. III).

Seed 003: "the Waypoint controller causes each point to be visited once, whereas the Orbit controller
provides a continuous orbit of a set of points. Thus, the Waypoint controller is activated for visit
location tasks and the Orbit controller is activated for patrol tasks." Here both controllers are TSTs
flown by the vehicle's own mission layer:

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

import json
from typing import Any

from companion.tst.spec import Mission, mission_from_dict

from .types import GeoPoint, TaskKind, TeamTask

#: speed name of a task without a speed of its own
DEFAULT_SPEED = "standard"


def _altitude(task: TeamTask, point: GeoPoint, fallback: float) -> float:
    if len(point) > 2 and point[2] > 0:
        return float(point[2])
    return task.altitude if task.altitude > 0 else fallback


def _speed_params(task: TeamTask) -> dict[str, Any]:
    return {"commanded_speed": float(task.speed)} if task.speed > 0 else {"speed": DEFAULT_SPEED}


def task_node(task: TeamTask, standard_altitude: float) -> dict[str, Any]:
    """The TST node (a dict in the mission-file format) that flies ``task``."""
    tid = f"task{task.id}"
    if task.kind is TaskKind.VISIT:
        p = task.points[0]
        return {"type": "fly-to", "id": tid,
                "params": {"position": [p[0], p[1], _altitude(task, p, standard_altitude)],
                           "fly_straight_line_flag": True, **_speed_params(task)}}
    if task.kind in (TaskKind.PATROL_LINE, TaskKind.BORDER_PIECE):
        wps = [[p[0], p[1], _altitude(task, p, standard_altitude)] for p in task.points]
        return {"type": "scan-ground", "id": tid,
                "params": {"waypoints_scan_flag": True, "waypoints": wps, "segment_flag": False,
                           "repeat_flag": True, "loiter_mode": "pass",
                           "speed": "standard",
                           "data_uuid": f"team-task-{task.id}"}}
    if task.kind is TaskKind.AREA_PART:
        return {"type": "scan-ground", "id": tid,
                "params": {"area": [[p[0], p[1]] for p in task.points], "speed": "standard",
                           "altitude": "standard", "data_uuid": f"team-task-{task.id}"}}
    if task.kind is TaskKind.TST:
        if not task.tst:
            raise ValueError(f"team task {task.id}: a TST task without its tree")
        tree = json.loads(task.tst)
        return tree.get("tree", tree) if isinstance(tree, dict) else tree
    raise ValueError(f"team task {task.id}: unknown kind {task.kind!r}")


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
