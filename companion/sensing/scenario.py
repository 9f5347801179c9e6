"""A scenario: the objects placed in the world for the simulated sensors (seed 000 Sec. VII).

Seed 000's scan-and-search mission looks for "salient points (e.g. a missing person)" in an area; in
simulation the salient points are declared in a YAML file and the simulated camera
(:mod:`companion.sensing.camera`) reports those in its view. The format::

    home: [58.3950, 15.5720]            # optional: lat, lon [, alt]; needed by `geopoint`
    objects:
      - {id: 7, class: person, position: [12.0, 8.5]}        # local metres north, east [, down]
      - {id: 8, class: car, geopoint: [58.39512, 15.57231]}  # lat, lon, converted around home

``id`` is an integer or a symbol (it becomes the object of the beliefs ``object(7, person)``,
``position(7, (n, e, d))``, ``visible(7)``), unique in the file; ``class`` is a symbol. Every problem
is a :class:`~taskflight_common.yamlio.ConfigError` naming file, line and field. Geopoints are converted to
local NED with the project's geodesy (:mod:`taskflight_common.geo`, ArduPilot's conversion).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from companion.behaviors.belief_syntax import Belief, BeliefError
from taskflight_common.geo import geodetic_to_ned
from taskflight_common.yamlio import ConfigError, Fields, load_yaml, load_yaml_text

ObjectId = int | str


@dataclass(frozen=True)
class SceneObject:
    """One object of the scenario: its id, class and position (local NED metres, ``d`` = 0 on the ground)."""

    id: ObjectId
    cls: str
    n: float
    e: float
    d: float = 0.0

    @property
    def position(self) -> tuple[float, float, float]:
        return (self.n, self.e, self.d)


class Scenario:
    """The objects of a scenario, by id (ids unique)."""

    def __init__(self, objects: Iterable[SceneObject] = ()) -> None:
        self.objects: dict[ObjectId, SceneObject] = {}
        for o in objects:
            if o.id in self.objects:
                raise ValueError(f"object id {o.id!r} used twice")
            _check_names(o.id, o.cls)
            self.objects[o.id] = o

    def __len__(self) -> int:
        return len(self.objects)

    def __iter__(self) -> Iterator[SceneObject]:
        return iter(self.objects.values())

    @classmethod
    def load(cls, path: str | Path, home: Sequence[float] | None = None) -> Scenario:
        """Read a scenario file; ``home`` (lat, lon[, alt]) is used when the file has none."""
        return scenario_from_data(load_yaml(path), str(path), home)

    @classmethod
    def from_text(cls, text: str, file: str = "<input>", home: Sequence[float] | None = None) -> Scenario:
        return scenario_from_data(load_yaml_text(text, file), file, home)


def _check_names(obj_id: Any, cls_name: Any) -> None:
    if isinstance(obj_id, bool) or not isinstance(obj_id, int | str):
        raise BeliefError(f"id {obj_id!r} must be an integer or a symbol")
    if not isinstance(cls_name, str) or not cls_name.isidentifier():
        raise BeliefError(f"class {cls_name!r} must be a symbol (letters, digits, _)")
    Belief("object", (obj_id, cls_name))


def _home(f: Fields, home: Sequence[float] | None) -> tuple[float, float, float] | None:
    if f.has("home"):
        raw = f.raw("home")
        n = len(raw) if isinstance(raw, list) else 0
        vec = f.vector("home", 3 if n == 3 else 2)
        lat, lon = vec[0], vec[1]
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            raise f.error("home", f"latitude/longitude out of range: {lat}, {lon}")
        return (lat, lon, vec[2] if len(vec) == 3 else 0.0)
    if home is not None:
        return (float(home[0]), float(home[1]), float(home[2]) if len(home) > 2 else 0.0)
    return None


def _object(f: Fields, home: tuple[float, float, float] | None) -> SceneObject:
    f.unknown(["id", "class", "position", "geopoint"])
    obj_id = f.raw("id")
    if isinstance(obj_id, bool) or not isinstance(obj_id, int | str):
        raise f.error("id", "expected an integer or a symbol")
    cls_name = f.string("class")
    try:
        _check_names(obj_id, cls_name)
    except BeliefError as exc:
        raise f.error("class" if "class" in str(exc) else "id", str(exc)) from None
    if f.has("position") == f.has("geopoint"):
        raise f.error(None, "give exactly one of 'position' ([north, east] metres) "
                      "or 'geopoint' ([lat, lon])")
    if f.has("position"):
        raw = f.raw("position")
        vec = f.vector("position", 3 if isinstance(raw, list) and len(raw) == 3 else 2)
        return SceneObject(obj_id, cls_name, vec[0], vec[1], vec[2] if len(vec) == 3 else 0.0)
    lat, lon = f.vector("geopoint", 2)
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise f.error("geopoint", f"latitude/longitude out of range: {lat}, {lon}")
    if home is None:
        raise f.error("geopoint", "a geopoint needs a home (the file's 'home' or the vehicle's)")
    n, e, _ = geodetic_to_ned(home, lat, lon, home[2])
    if not (math.isfinite(n) and math.isfinite(e)):
        raise f.error("geopoint", "cannot convert to local coordinates")
    return SceneObject(obj_id, cls_name, n, e, 0.0)


def scenario_from_data(data: Any, file: str = "<input>", home: Sequence[float] | None = None) -> Scenario:
    """Build a scenario from parsed YAML (see the module docstring for the format)."""
    top = Fields(data, "", file)
    top.unknown(["home", "objects"])
    origin = _home(top, home)
    raw = top.raw("objects")
    if not isinstance(raw, list):
        raise top.error("objects", "expected a list of objects")
    objects: list[SceneObject] = []
    seen: dict[ObjectId, int] = {}
    for i, item in enumerate(raw):
        line = raw.line_of(i) if hasattr(raw, "line_of") else None
        o = _object(Fields(item, f"objects[{i}]", file, line), origin)
        if o.id in seen:
            raise ConfigError(file, line, f"objects[{i}].id",
                              f"id {o.id!r} already used by objects[{seen[o.id]}]")
        seen[o.id] = i
        objects.append(o)
    return Scenario(objects)
