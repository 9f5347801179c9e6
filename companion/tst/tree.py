"""Task Specification Trees (seed 000 Sec. III, Fig. 2): ``TstNode``, control nodes and leaves.

"Inner nodes in a TST can specify standardized control structures such as sequences (S), concurrent
execution (C), conditionals (IF) and loops (WHILE). Leaf nodes declaratively specify potentially
domain-specific tasks to be executed". Every node has an id, a type, parameters and its children:

* ``S`` and ``C``: one or more children, run in order (S) or concurrently (C);
* ``IF``: a ``condition`` (a belief query, e.g. ``visible(?x), object(?x, person)``), the *then* child and
  an optional *else* child (``children[0]``, ``children[1]``);
* ``WHILE``: a ``condition`` and one child, the body;
* a leaf: a registered task type (:mod:`companion.tst.registry`) with its checked parameters. A leaf
  may get children only by ``expand()`` ("These are then returned and appended to the tree", Sec. III-A),
  through :meth:`TstNode.append_child`.

Every node may say how often its execution is tried again when it fails (``retries``, ours: seed 000 has no
retry; 0 by default, at most :data:`MAX_RETRIES`): a failed node is run again from its start up to
``retries`` times before its failure ends its parent (:mod:`companion.tst.execution`). An aborted node is
never retried.

Ids are unique in a tree. A node built without one gets an automatic id ``n1``, ``n2``, ... in preorder
(explicit ids are kept and skipped); a duplicate explicit id is refused with :class:`TreeError`. Nodes
appended later (``append_child``) keep the ids already handed out and get the next free numbers.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from companion.tst.params import constraint_to_json, is_free
from companion.tst.registry import is_leaf_type, leaf_type, leaf_type_names


class ControlType(StrEnum):
    """Seed 000 Sec. II's control nodes: sequence (S), concurrent (C), conditional (IF), loop (WHILE).

    The leaf task types are registered (:mod:`companion.tst.registry`); the four control types are the
    tree's own and fixed, so they are an enumeration: code asks :attr:`TstNode.control`, never compares
    the type's string.
    """

    S = "S"
    C = "C"
    IF = "IF"
    WHILE = "WHILE"


#: The control node types and how many children each takes (min, max; None: no maximum).
CONTROL_TYPES: dict[str, tuple[int, int | None]] = {
    ControlType.S: (1, None), ControlType.C: (1, None), ControlType.IF: (1, 2), ControlType.WHILE: (1, 1)}
#: Node types that carry a condition.
CONDITIONAL_TYPES = (ControlType.IF, ControlType.WHILE)


def control_type(node_type: str) -> ControlType | None:
    """The control type named ``node_type``; None for a leaf task type."""
    return ControlType(node_type) if node_type in CONTROL_TYPES else None

_AUTO_ID = re.compile(r"n(\d+)")
#: the most retries a node may ask for
MAX_RETRIES = 10


class TreeError(ValueError):
    """A malformed tree: an unknown type, a duplicate id, a wrong number of children, a missing condition."""


def known_types() -> tuple[str, ...]:
    """Every node type: the control types, then the leaf task types."""
    return (*CONTROL_TYPES, *leaf_type_names())


@dataclass(eq=False)
class TstNode:
    """One node of a TST (Sec. III): ``id``, ``type``, ``params``, ``children``, ``parent``, ``condition``.

    Leaf parameters are checked against the task type when the node is built
    (:meth:`~companion.tst.leaves.base.LeafType.validate`, raising
    :class:`~companion.tst.params.ParamError`), so ``params`` always holds normalized values or constraints
    with the defaults filled in.
    """

    type: str
    params: dict[str, Any] = field(default_factory=dict)
    children: list[TstNode] = field(default_factory=list)
    id: str | None = None
    condition: str | None = None
    parent: TstNode | None = field(default=None, repr=False)
    _auto_id: bool = field(default=False, repr=False)
    #: how many times a failed execution of this node is started again (module docstring)
    retries: int = 0

    def __post_init__(self) -> None:
        if self.type not in CONTROL_TYPES and not is_leaf_type(self.type):
            raise TreeError(f"unknown task type '{self.type}' (known: {', '.join(known_types())})")
        if self.is_control:
            if self.params:
                raise TreeError(f"a {self.type} node has no parameters")
            maximum = CONTROL_TYPES[self.type][1]
            if maximum is not None and len(self.children) > maximum:
                raise TreeError(f"a {self.type} node has at most {maximum} child{'ren' * (maximum > 1)}, "
                                f"got {len(self.children)}")
        else:
            self.params = leaf_type(self.type).validate(self.params)
        if isinstance(self.retries, bool) or not isinstance(self.retries, int) \
                or not 0 <= self.retries <= MAX_RETRIES:
            raise TreeError(f"retries: a whole number from 0 to {MAX_RETRIES}, got {self.retries!r}")
        if self.condition is not None and self.type not in CONDITIONAL_TYPES:
            raise TreeError(f"only IF and WHILE nodes have a condition, not {self.type}")
        if self.id is None:
            self._auto_id = True
        elif not isinstance(self.id, str) or not self.id.strip():
            raise TreeError(f"a node id is a non-empty string, got {self.id!r}")
        self.children = list(self.children)
        for child in self.children:
            if child.parent is not None:
                raise TreeError(f"node {child.id} already has a parent")
        _number(self, taken=set())
        for child in self.children:
            child.parent = self

    # --- kinds -------------------------------------------------------------------------------------------
    @property
    def is_control(self) -> bool:
        return self.type in CONTROL_TYPES

    @property
    def control(self) -> ControlType | None:
        """The control type of a control node; None for a leaf task."""
        return control_type(self.type)

    @property
    def is_leaf_task(self) -> bool:
        return is_leaf_type(self.type)

    @property
    def then(self) -> TstNode | None:
        """An IF node's *then* child."""
        return self.children[0] if self.control is ControlType.IF and self.children else None

    @property
    def else_(self) -> TstNode | None:
        """An IF node's *else* child, if any."""
        return self.children[1] if self.control is ControlType.IF and len(self.children) > 1 else None

    @property
    def body(self) -> TstNode | None:
        """A WHILE node's body."""
        return self.children[0] if self.control is ControlType.WHILE and self.children else None

    def free_params(self) -> dict[str, Any]:
        """The parameters holding a constraint rather than a value."""
        return {name: value for name, value in self.params.items() if is_free(value)}

    # --- walking -----------------------------------------------------------------------------------------
    @property
    def root(self) -> TstNode:
        node = self
        while node.parent is not None:
            node = node.parent
        return node

    def iter(self) -> Iterator[TstNode]:
        """This node and all below it, in preorder."""
        stack = [self]
        while stack:
            node = stack.pop()
            yield node
            stack.extend(reversed(node.children))

    def find(self, node_id: str) -> TstNode | None:
        """The node with ``node_id`` in this subtree, or None."""
        return next((n for n in self.iter() if n.id == node_id), None)

    def path(self) -> list[TstNode]:
        """The nodes from the root down to this one (both included)."""
        out = [self]
        while out[-1].parent is not None:
            out.append(out[-1].parent)
        return out[::-1]

    def depth(self) -> int:
        return len(self.path()) - 1

    # --- expansion -----------------------------------------------------------------------------------------
    def append_child(self, child: TstNode) -> TstNode:
        """Append ``child`` (and its subtree) under this node, as ``expand()`` does (Sec. III-A).

        The child's nodes without an explicit id get the next free automatic ids of the whole tree; an
        explicit id already used in the tree is refused with :class:`TreeError`, and the tree is unchanged.
        """
        if child.parent is not None:
            raise TreeError(f"node {child.id} already has a parent")
        if any(n is child for n in self.path()):
            raise TreeError("a node cannot be appended below itself")
        maximum = CONTROL_TYPES.get(self.type, (0, None))[1]
        if maximum is not None and len(self.children) >= maximum:
            raise TreeError(f"a {self.type} node has at most {maximum} child{'ren' * (maximum > 1)}")
        root = self.root
        existing = {n.id for n in root.iter()}
        for node in child.iter():
            if not node._auto_id and node.id in existing:
                raise TreeError(f"duplicate node id '{node.id}'")
        numbers = [int(m.group(1)) for i in existing if i and (m := _AUTO_ID.fullmatch(i))]
        taken = {i for i in existing if i} | {n.id for n in child.iter() if not n._auto_id and n.id}
        counter = itertools.count(max(numbers, default=0) + 1)
        for node in child.iter():
            if node._auto_id:
                node.id = _next_free(counter, taken)
        child.parent = self
        self.children.append(child)
        return child

    # --- JSON -------------------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The JSON form of this subtree (the mission format of :mod:`companion.tst.spec`)."""
        out: dict[str, Any] = {"id": self.id, "type": self.type}
        if self.retries:
            out["retries"] = self.retries
        if self.condition is not None:
            out["condition"] = self.condition
        if self.is_leaf_task:
            if self.params:
                out["params"] = {k: param_to_json(v) for k, v in self.params.items()}
            if self.children:
                out["expansion"] = [c.to_dict() for c in self.children]
        elif self.control is ControlType.IF:
            out["then"] = self.children[0].to_dict() if self.children else None
            if len(self.children) > 1:
                out["else"] = self.children[1].to_dict()
        elif self.control is ControlType.WHILE:
            out["body"] = self.children[0].to_dict() if self.children else None
        else:
            out["children"] = [c.to_dict() for c in self.children]
        return out

    def __repr__(self) -> str:
        return f"TstNode({self.id!r}, {self.type!r}, {len(self.children)} children)"


def param_to_json(value: Any) -> Any:
    """A parameter value (or constraint) in JSON form: tuples become lists, constraints mappings."""
    if is_free(value):
        return constraint_to_json(value)
    if isinstance(value, tuple | list):
        return [param_to_json(v) for v in value]
    return value


def check_structure(root: TstNode) -> None:
    """Raise :class:`TreeError` unless every control node has its children and IF/WHILE a condition."""
    for node in root.iter():
        if node.is_control:
            lo, _ = CONTROL_TYPES[node.type]
            if len(node.children) < lo:
                raise TreeError(f"node {node.id}: a {node.type} node needs at least {lo} child")
        if node.type in CONDITIONAL_TYPES and not node.condition:
            raise TreeError(f"node {node.id}: a {node.type} node needs a condition")


def _number(root: TstNode, taken: set[str]) -> None:
    """(Re)number the automatic ids of a subtree being built, in preorder; refuse duplicate explicit ids."""
    explicit: set[str] = set()
    for node in root.iter():
        if not node._auto_id:
            if node.id in explicit:
                raise TreeError(f"duplicate node id '{node.id}'")
            explicit.add(node.id)  # type: ignore[arg-type]
    taken = taken | explicit
    counter = itertools.count(1)
    for node in root.iter():
        if node._auto_id:
            node.id = _next_free(counter, taken)


def _next_free(counter: Iterator[int], taken: set[str]) -> str:
    for k in counter:
        candidate = f"n{k}"
        if candidate not in taken:
            taken.add(candidate)
            return candidate
    raise AssertionError("unreachable")  # pragma: no cover
