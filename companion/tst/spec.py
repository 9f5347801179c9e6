"""The mission format: a TST in YAML (or JSON), validated with errors naming file, line and field.

A mission file (``mission_specs/*.yaml``)::

    mission: scan-and-search             # the mission's name (required)
    description: Fig. 15 of seed 000     # optional
    on_failure: land                     # optional: hover (default) | land | rtl, see below
    tree:                                # the root node (required)
      type: S
      id: root                           # optional on every node; default n1, n2, ... in preorder
      children:                          # S and C: one or more children
        - {type: take-off}
        - type: scan-ground
          params: {area: [[58.3950, 15.5730], [58.3950, 15.5732], [58.3951, 15.5731]],
                   speed: standard, altitude: standard, sensor_type: camera}
        - type: WHILE                    # IF / WHILE: condition (a belief query) ...
          condition: "visible(?x), object(?x, person)"
          body: {type: hover, params: {duration: 5}}     # ... WHILE: body (one node)
        - type: IF
          condition: "visible(?x)"
          then: {type: request-operator-assistance, params: {message: "person found"}}
          else: {type: wait, params: {duration: 1}}      # IF: then, optional else
        - {type: fly-to, params: {position: [58.3951, 15.5733, 3.0], speed: fast,
                                  fly_straight_line_flag: true}}
        - {type: land, params: {land_at_current_position_flag: true}}

Node keys: ``type`` (a control type S, C, IF, WHILE or a task type of
:mod:`companion.tst.registry`), ``id``, ``retries`` (every node: how often a failed execution is tried
again, 0..10, default 0), ``params`` (leaves), ``children`` (S, C), ``condition``
(IF, WHILE), ``then`` / ``else`` (IF), ``body`` (WHILE), and ``expansion`` (leaves: the nodes ``expand()``
appended, as :func:`mission_to_dict` writes them, so that a dumped expanded tree loads again). Parameter
values and constraints are those of :mod:`companion.tst.params` (``speed: "slow | standard"``,
``commanded_speed: {interval: [1, 3]}``, ``duration: "duration <= endurance_left"``).

What a failure does (ours; seed 000 leaves it to the platform): once the mission fails (a node failed
after its retries) or is aborted, the execution system applies ``on_failure``: ``hover`` holds where the
vehicle is (the executive layer's default KEEP_HOVERING, as before), ``land`` asks for LAND, ``rtl`` for the
RTL behavior (:mod:`companion.tst.execution`).

Every problem is a :class:`~taskflight_common.yamlio.ConfigError` ``file:line: field: reason``: unknown
keys, an
unknown node type, a parameter unknown to the task type, a missing required parameter, a bad geopoint, a
control node without children, IF/WHILE without a condition or with a malformed one
(:func:`companion.tst.conditions.parse_condition`: a belief query, or ``not`` a query), and duplicate
ids. JSON bodies (the companion's ``POST /mission``) go through :func:`mission_from_dict` and get the
same checks without line numbers.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from companion.behaviors.belief_syntax import BeliefError
from companion.tst.conditions import parse_condition
from companion.tst.params import ParamError
from companion.tst.registry import is_leaf_type
from companion.tst.tree import (
    CONDITIONAL_TYPES,
    CONTROL_TYPES,
    MAX_RETRIES,
    ControlType,
    TreeError,
    TstNode,
    control_type,
    known_types,
)
from taskflight_common.yamlio import ConfigError, Fields, LineList, load_yaml, load_yaml_text

log = logging.getLogger(__name__)

MISSION_KEYS = ("mission", "description", "on_failure", "tree")
#: What a failed or aborted mission does (``on_failure``); the first is the default.
FAILURE_POLICIES = ("hover", "land", "rtl")
#: The keys a node of each kind may have.
NODE_KEYS: dict[str, tuple[str, ...]] = {
    "S": ("type", "id", "retries", "children"),
    "C": ("type", "id", "retries", "children"),
    "IF": ("type", "id", "retries", "condition", "then", "else"),
    "WHILE": ("type", "id", "retries", "condition", "body"),
    "leaf": ("type", "id", "retries", "params", "expansion"),
}


@dataclass
class Mission:
    """A named TST (the ``mission:`` and ``tree:`` of a mission file)."""

    name: str
    root: TstNode
    description: str = ""
    #: what a failure or an abort does: one of :data:`FAILURE_POLICIES`
    on_failure: str = FAILURE_POLICIES[0]

    def __post_init__(self) -> None:
        if self.on_failure not in FAILURE_POLICIES:
            raise ValueError(f"on_failure: one of {', '.join(FAILURE_POLICIES)}, got {self.on_failure!r}")


def load_mission(path: str | Path) -> Mission:
    """Read and validate a mission file; raises :class:`ConfigError` naming file, line and field."""
    data = load_yaml(path)
    mission = mission_from_dict(data, str(path))
    log.info("loaded mission %s from %s (%d nodes)", mission.name, path, sum(1 for _ in mission.root.iter()))
    return mission


def mission_from_yaml(text: str, file: str = "<input>") -> Mission:
    """Parse and validate mission YAML text."""
    return mission_from_dict(load_yaml_text(text, file), file)


def mission_from_dict(data: Any, file: str | None = None) -> Mission:
    """Validate a mission given as data (parsed YAML keeping lines, or a JSON body without them)."""
    top = Fields(data, "", file or "<input>")
    top.unknown(MISSION_KEYS)
    name = top.string("mission")
    if not name.strip():
        raise top.error("mission", "the mission needs a name")
    description = top.string("description", "")
    on_failure = top.string("on_failure", FAILURE_POLICIES[0], choices=FAILURE_POLICIES)
    root = _Builder(top.file).node(top.sub("tree"))
    return Mission(name, root, description, on_failure)


def mission_to_dict(mission: Mission) -> dict[str, Any]:
    """The JSON form of a mission (``mission_from_dict`` reads it back)."""
    out: dict[str, Any] = {"mission": mission.name}
    if mission.description:
        out["description"] = mission.description
    if mission.on_failure != FAILURE_POLICIES[0]:
        out["on_failure"] = mission.on_failure
    out["tree"] = mission.root.to_dict()
    return out


class _Builder:
    """Builds the tree bottom-up, remembering where each explicit id stood to report duplicates."""

    def __init__(self, file: str | None) -> None:
        self.file = file
        self.ids: dict[str, int | None] = {}

    def node(self, f: Fields) -> TstNode:
        node_type = f.string("type")
        if node_type not in CONTROL_TYPES and not is_leaf_type(node_type):
            raise f.error("type", f"unknown task type '{node_type}' (known: {', '.join(known_types())})")
        f.unknown(NODE_KEYS.get(node_type, NODE_KEYS["leaf"]))
        node_id = self._id(f)
        retries = f.integer("retries", 0, lo=0, hi=MAX_RETRIES)
        condition = self._condition(f, node_type) if node_type in CONDITIONAL_TYPES else None
        children = self._children(f, node_type)
        params = self._params(f, node_type) if is_leaf_type(node_type) else {}
        try:
            return TstNode(node_type, params=params, children=children, id=node_id, condition=condition,
                           retries=retries)
        except ParamError as exc:
            raise self._param_error(f, exc) from None
        except TreeError as exc:
            raise f.error(None, str(exc)) from None

    def _id(self, f: Fields) -> str | None:
        if not f.has("id"):
            return None
        value = f.raw("id")
        if isinstance(value, bool) or not isinstance(value, str | int) or not str(value).strip():
            raise f.error("id", f"a node id is a non-empty string, got {value!r}")
        node_id = str(value)
        if node_id in self.ids:
            first = self.ids[node_id]
            where = f" (first at line {first})" if first is not None else ""
            raise f.error("id", f"duplicate node id '{node_id}'{where}")
        self.ids[node_id] = f.line("id")
        return node_id

    def _condition(self, f: Fields, node_type: str) -> str:
        if not f.has("condition"):
            raise f.error(None, f"a {node_type} node needs a condition (a belief query)")
        text = f.string("condition")
        try:
            parse_condition(text)
        except BeliefError as exc:
            raise f.error("condition", str(exc)) from None
        return text

    def _children(self, f: Fields, node_type: str) -> list[TstNode]:
        control = control_type(node_type)
        if control is ControlType.IF:
            if not f.has("then"):
                raise f.error(None, "an IF node needs a then child")
            out = [self.node(f.sub("then"))]
            if f.has("else"):
                out.append(self.node(f.sub("else")))
            return out
        if control is ControlType.WHILE:
            if not f.has("body"):
                raise f.error(None, "a WHILE node needs a body")
            return [self.node(f.sub("body"))]
        key = "children" if node_type in CONTROL_TYPES else "expansion"
        if not f.has(key):
            if node_type in CONTROL_TYPES:
                raise f.error(None, f"a {node_type} node needs children")
            return []
        items = f.raw(key)
        if not isinstance(items, list):
            raise f.error(key, "expected a list of nodes")
        if not items and node_type in CONTROL_TYPES:
            raise f.error(key, f"a {node_type} node needs at least one child")
        line_of = items.line_of if isinstance(items, LineList) else (lambda _i: f.line(key))
        return [self.node(Fields(item, f"{f.path(key)}[{i}]", self.file, line_of(i)))
                for i, item in enumerate(items)]

    def _params(self, f: Fields, node_type: str) -> dict[str, Any]:
        if not f.has("params"):
            return {}
        params = f.raw("params")
        if params is None:
            return {}
        return dict(Fields(params, f.path("params"), self.file, f.line("params")).data)

    def _param_error(self, f: Fields, exc: ParamError) -> ConfigError:
        params = f.raw("params", None)
        pf = Fields(params if isinstance(params, Mapping) else {}, f.path("params"), self.file,
                    f.line("params") or f.line())
        key = exc.field
        line = pf.line(key) if key is not None and key in pf.data else pf.line()
        value = pf.data.get(key) if key is not None else None
        if exc.index is not None and isinstance(value, LineList):
            line = value.line_of(exc.index)
        return ConfigError(self.file, line, pf.path(key) if key else pf.prefix, exc.reason)

