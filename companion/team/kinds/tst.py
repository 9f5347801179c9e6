"""A Task Specification Tree given to the team (seed 000 Sec. III): flown as given; a C root is divided,
one task per child, so that its children are delegated to different vehicles."""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from companion.team.types import GeoPoint, TaskKind, TeamTask
from companion.tst.spec import mission_from_dict

from .base import Route, TeamTaskKind, piece_name, with_altitude

if TYPE_CHECKING:
    from companion.team.tasks import TaskDef


def tst_points(tst_json: str | None) -> list[GeoPoint]:
    """The geopoints of a TST in preorder: fly-to ``position`` and scan-ground ``area`` vertices."""
    if not tst_json:
        return []
    out: list[GeoPoint] = []

    def walk(node: object) -> None:
        if not isinstance(node, dict):
            return
        params = node.get("params") or {}
        pos = params.get("position") if isinstance(params, dict) else None
        if isinstance(pos, list | tuple) and len(pos) >= 2:
            out.append((float(pos[0]), float(pos[1]), float(pos[2]) if len(pos) > 2 else 0.0))
        area = params.get("area") if isinstance(params, dict) else None
        if isinstance(area, list | tuple):
            out.extend((float(p[0]), float(p[1]), 0.0) for p in area if isinstance(p, list | tuple))
        for child in node.get("children") or []:
            walk(child)
        for key in ("then", "else", "body"):
            walk(node.get(key))

    walk(json.loads(tst_json))
    return out


def _c_root(tree: Mapping[str, Any]) -> bool:
    return bool(tree.get("type") == "C" and tree.get("children"))


class Tst(TeamTaskKind):
    name = "tst"
    task_kind = TaskKind.TST
    wire_code = 4
    directable = False  # a tree is given to one vehicle through its mission service instead

    def points(self, defn: TaskDef) -> tuple[GeoPoint, ...]:
        if not isinstance(defn.tree, Mapping):
            raise ValueError("tree: a tst task needs a tree (a mapping)")
        return tuple(tst_points(json.dumps(defn.tree)))

    def check(self, defn: TaskDef, pts: Sequence[GeoPoint]) -> None:
        pass  # the tree is checked by the mission layer when divided

    def is_group(self, defn: TaskDef) -> bool:
        return isinstance(defn.tree, Mapping) and _c_root(defn.tree)

    def divide(self, defn: TaskDef, pts: tuple[GeoPoint, ...], ids: Iterator[int], group: int,
               common: dict[str, Any]) -> list[TeamTask]:
        tree = dict(defn.tree or {})
        name = defn.name
        mission_from_dict({"mission": name or "team-task", "tree": tree})  # ConfigError (a ValueError)
        if _c_root(tree):
            children = tree["children"]
            return [TeamTask(id=next(ids), kind=self.task_kind, points=tuple(tst_points(json.dumps(c))[:1]),
                             group=group, group_size=len(children), tst=json.dumps(c),
                             name=piece_name(name, k), **common)
                    for k, c in enumerate(children)]
        return [TeamTask(id=next(ids), kind=self.task_kind, points=pts[:1], tst=json.dumps(tree), name=name,
                         **common)]

    def task_points(self, task: TeamTask) -> Sequence[GeoPoint]:
        return task.points or tst_points(task.tst)

    def route(self, task: TeamTask, at: GeoPoint) -> Route:
        """Its points in order (the first replaced by the entry point)."""
        entry = self.entry_point(task, at)
        pts = [with_altitude(task, p) for p in tst_points(task.tst)] or [entry]
        return Route([entry, *pts[1:]])

    def node(self, task: TeamTask, standard_altitude: float) -> dict[str, Any]:
        if not task.tst:
            raise ValueError(f"team task {task.id}: a TST task without its tree")
        tree = json.loads(task.tst)
        return tree.get("tree", tree) if isinstance(tree, dict) else tree
