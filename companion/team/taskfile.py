"""The team task file (YAML) for the team simulator and the team-control station.

::

    team: seed-003-demo                      # a name (optional)
    home: [-35.363261, 149.165230]           # the vehicles' start / datum (optional; sim)
    fence: [[lat, lon], [lat, lon], ...]     # the operational envelope (optional): tasks outside rejected
    tasks:
      - name: visit-north                    # optional
        kind: visit                          # visit | patrol_line | border_patrol | area_scan | tst
        points: [[-35.3610, 149.1652]]       # [lat, lon] or [lat, lon, alt]
        altitude: 20                         # m above the datum (optional)
        speed: 0                             # m/s along the task (optional, 0: the vehicle's)
        n: 2                                 # border_patrol / area_scan: vehicles to divide among
        tree: {type: C, children: [...]}     # tst: a Task Specification Tree (seed 000)
        at: 0                                # s after the start when the operator adds it
        cancel_at: 120                       # s after the start when the operator cancels it (optional)

Read through :mod:`taskflight_common.yamlio`: every problem is a
:class:`~taskflight_common.yamlio.ConfigError`
``file:line: field: reason`` (the task's checks of :func:`companion.team.tasks.divide` included: a task
outside the fence, N = 0, a polygon that is not simple ...).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from shapely.geometry import Polygon

from companion.team.tasks import DEF_KINDS, Fence, TaskDef, divide
from taskflight_common.yamlio import ConfigError, Fields, load_yaml, load_yaml_text

TOP_KEYS = ("team", "home", "fence", "tasks")
TASK_KEYS = ("name", "kind", "points", "altitude", "speed", "n", "tree", "at", "cancel_at")


@dataclass(frozen=True)
class ScriptedTask:
    """One operator task with its add time and optional cancel time (s after the start)."""

    defn: TaskDef
    at: float = 0.0
    cancel_at: float | None = None
    line: int | None = None


@dataclass(frozen=True)
class TaskScript:
    name: str
    home: tuple[float, float] | None
    fence: Fence | None
    tasks: tuple[ScriptedTask, ...]


def load_task_file(path: str | Path) -> TaskScript:
    """Read a team task file (module doc); raises ConfigError naming file, line and field."""
    return task_script_from_dict(load_yaml(path), str(path))


def task_script_from_yaml(text: str, file: str = "<input>") -> TaskScript:
    return task_script_from_dict(load_yaml_text(text, file), file)


def _points(f: Fields, key: str) -> tuple[tuple[float, ...], ...]:
    raw = f.raw(key)
    if not isinstance(raw, list) or not raw:
        raise f.error(key, "expected a list of [lat, lon] or [lat, lon, alt]")
    out = []
    for i, p in enumerate(raw):
        if not isinstance(p, list) or len(p) not in (2, 3) or not all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in p):
            line = raw.line_of(i) if hasattr(raw, "line_of") else f.line(key)
            raise ConfigError(f.file, line, f"{f.path(key)}[{i}]", f"expected [lat, lon] or [lat, lon, alt], "
                                                                    f"got {p!r}")
        out.append(tuple(float(v) for v in p))
    return tuple(out)


def task_script_from_dict(data: Any, file: str | None = None) -> TaskScript:
    f = Fields(data, file=file)
    f.unknown(TOP_KEYS)
    name = f.string("team", "")
    home = f.vector("home", 2, None) if f.has("home") else None
    fence = None
    if f.has("fence"):
        pts = _points(f, "fence")
        poly = Polygon([(p[0], p[1]) for p in pts])
        if len(pts) < 3 or not poly.is_valid or poly.area <= 0:
            raise f.error("fence", "expected a simple polygon of at least 3 [lat, lon] points")
        fence = Fence(poly)
    raw_tasks = f.raw("tasks")
    if not isinstance(raw_tasks, list):
        raise f.error("tasks", "expected a list of tasks")
    items = []
    for i, raw in enumerate(raw_tasks):
        line = raw_tasks.line_of(i) if hasattr(raw_tasks, "line_of") else None
        t = Fields(raw, f"tasks[{i}]", f.file, line)
        t.unknown(TASK_KEYS)
        kind = t.string("kind", choices=DEF_KINDS)
        tree = t.raw("tree", None)
        defn = TaskDef(kind=kind, points=_points(t, "points") if t.has("points") else (),
                       n=t.integer("n", 1, lo=1), altitude=t.number("altitude", 0.0, lo=0.0),
                       speed=t.number("speed", 0.0, lo=0.0), name=t.string("name", ""),
                       tree=_plain(tree) if tree is not None else None)
        at = t.number("at", 0.0, lo=0.0)
        cancel_at = t.number("cancel_at", None) if t.has("cancel_at") else None
        if cancel_at is not None and cancel_at < at:
            raise t.error("cancel_at", f"must be >= at ({at:g}), got {cancel_at:g}")
        try:
            divide(defn, itertools.count(1), fence)
        except ConfigError as exc:
            raise ConfigError(f.file, t.line("tree"), f"tasks[{i}].tree", exc.reason) from exc
        except ValueError as exc:
            msg = str(exc)
            key = msg.split(":", 1)[0].split("[", 1)[0]
            where = key if key in TASK_KEYS else None
            raise ConfigError(f.file, t.line(where) if where else line,
                              f"tasks[{i}].{msg.split(':', 1)[0]}" if where else f"tasks[{i}]",
                              msg.split(":", 1)[1].strip() if where else msg) from exc
        items.append(ScriptedTask(defn, at, cancel_at, line))
    return TaskScript(name, (home[0], home[1]) if home else None, fence, tuple(items))


def _plain(x: Any) -> Any:
    """LineDict / LineList -> plain dict / list (JSON-able)."""
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_plain(v) for v in x]
    return x
