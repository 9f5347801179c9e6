"""The rest of a mission from one of its nodes, for ``POST /mission/resume`` (ours; seed 000 Sec. III-A).

Seed 000 lets a platform accept "a mission or a part of a mission" (Sec. III); a mission that failed or
was aborted at a node can be given again as the part that is left. :func:`remainder` builds it from the
mission as it was submitted (before delegation expanded it) and the outcome of each node's last run:

* the node itself, then, going up the tree, for each ancestor
* ``S``: the node (or what was built so far) followed by the siblings after it;
* ``C``: what was built so far beside the siblings that did not succeed;
* ``IF``: what was built so far (the branch was chosen; the condition is not evaluated again);
* ``WHILE``: resuming inside a loop's body is refused (resume from the WHILE node: its condition is
  evaluated again).

Ids, parameters, conditions and ``retries`` are kept, so the events and ``GET /mission`` name the same
nodes; the mission's name and ``on_failure`` too. The result is delegated again like any mission.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from companion.tst.spec import Mission, mission_from_dict
from companion.tst.tree import ControlType, TstNode


class ResumeError(ValueError):
    """The node cannot be resumed from (unknown, inside a WHILE body, or part of an expansion)."""


def _plain(node: TstNode) -> dict[str, Any]:
    """The node as it was written: no expansion (delegation expands it again)."""
    out = node.to_dict()
    _drop_expansions(out)
    return out


def _drop_expansions(tree: Any) -> None:
    if isinstance(tree, dict):
        tree.pop("expansion", None)
        for key in ("children", "then", "else", "body"):
            _drop_expansions(tree.get(key))
    elif isinstance(tree, list):
        for item in tree:
            _drop_expansions(item)


def remainder(mission: Mission, node_id: str, outcome: Callable[[str], str | None],
              take_off: dict[str, Any] | None = None) -> Mission:
    """The part of ``mission`` left from ``node_id`` on (module docstring). ``outcome(id)`` is the state of
    a node's last run (``succeeded``, ``failed``, ...; None: it never ran). ``take_off``: a take-off node
    (its JSON form) to fly first (the vehicle is on the ground)."""
    node = mission.root.find(node_id)
    if node is None:
        known = ", ".join(str(n.id) for n in mission.root.iter())
        raise ResumeError(f"node: no node '{node_id}' in mission {mission.name} (nodes: {known})")
    built = _plain(node)
    child = node
    for parent in reversed(node.path()[:-1]):
        kind = parent.control
        if kind is None:
            raise ResumeError(f"node: '{node_id}' is part of {parent.id}'s expansion: resume from "
                              f"{parent.id}")
        if kind is ControlType.WHILE:
            raise ResumeError(f"node: '{node_id}' is inside the loop {parent.id}: resume from {parent.id} "
                              "(its condition is evaluated again)")
        if kind is ControlType.IF:
            child = parent
            continue
        siblings = parent.children
        at = next(i for i, c in enumerate(siblings) if c is child)
        if kind is ControlType.S:
            rest = [_plain(c) for c in siblings[at + 1:]]
        else:  # C: the siblings that have not succeeded run again beside it
            rest = [_plain(c) for i, c in enumerate(siblings)
                    if i != at and outcome(str(c.id)) != "succeeded"]
        out: dict[str, Any] = {"type": parent.type, "id": parent.id, "children": [built, *rest]}
        if parent.retries:
            out["retries"] = parent.retries
        built = out
        child = parent
    if take_off is not None:
        ids = {str(n.id) for n in mission.root.iter()}
        wrapper = _free_id("resume", ids)
        built = {"type": "S", "id": wrapper,
                 "children": [{**take_off, "id": _free_id("resume-take-off", ids)}, built]}
    data: dict[str, Any] = {"mission": mission.name, "tree": built}
    if mission.description:
        data["description"] = mission.description
    data["on_failure"] = mission.on_failure
    return mission_from_dict(data, "<resume>")


def _free_id(base: str, taken: set[str]) -> str:
    name, k = base, 1
    while name in taken:
        k += 1
        name = f"{base}-{k}"
    taken.add(name)
    return name


def first_leaf(root: TstNode) -> TstNode | None:
    """The leaf a tree starts with (the first child of each control node on the way down)."""
    node = root
    while node.is_control and node.children:
        node = node.children[0]
    return node if not node.is_control else None
