"""The registry of leaf task types: the one place a task type's name is looked up (seed 000 Sec. III).

"Leaf nodes declaratively specify potentially domain-specific tasks to be executed" and "each of the
platforms participating in a mission has a set of executors for the tasks it can perform" (Sec. III-A).
A leaf task type is one object (a :class:`~companion.tst.leaves.base.LeafType`) that holds everything
the platform knows of the task: its parameters, its ``check()`` and ``get_constraints()``, its plan and
``expand()``, its Fig. 4 execution information and its executor. :func:`register` adds one (the bundled
types are registered by :mod:`companion.tst.leaves`; a new type is one more module that calls it) and
:func:`leaf_type` finds it by name. Nothing else compares task type names.

This module imports nothing of the project, so the tree (:mod:`companion.tst.tree`) can look types up
while the leaf modules build on the tree.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from companion.tst.leaves.base import LeafType

__all__ = ["is_leaf_type", "leaf_type", "leaf_type_names", "leaf_types", "register", "unregister"]

_REGISTRY: dict[str, LeafType] = {}


def register(leaf: LeafType) -> LeafType:
    """Add ``leaf`` under its ``name`` (a second registration of a name replaces the first); returns it."""
    if not isinstance(leaf.name, str) or not leaf.name.strip():
        raise ValueError(f"a leaf task type needs a name, got {leaf.name!r}")
    _REGISTRY[leaf.name] = leaf
    return leaf


def unregister(name: str) -> None:
    """Forget the leaf task type ``name`` (tests that define one remove it again)."""
    _REGISTRY.pop(name, None)


def leaf_type(name: str) -> LeafType:
    """The leaf task type called ``name``; KeyError naming the known ones if there is none."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise KeyError(f"unknown task type '{name}' (known: {', '.join(_REGISTRY)})") from None


def is_leaf_type(name: str) -> bool:
    return name in _REGISTRY


def leaf_types() -> tuple[LeafType, ...]:
    """Every registered leaf task type, in registration order."""
    return tuple(_REGISTRY.values())


def leaf_type_names() -> tuple[str, ...]:
    return tuple(_REGISTRY)
