"""A test leaf type whose failure the test controls: ``guarded-fly-to`` (no tests here).

A fly-to (seed 000 Sec. VI-B) that fails at its start while the belief ``clearance(self, granted)`` does
not hold: a precondition the operator can fix (``POST /beliefs``), so a node fails, is retried and
resumed for a reason the test sets. Register it with :func:`guarded_leaf` (a context manager).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from companion.tst.leaves.fly_to import FlyTo, FlyToExecutor
from companion.tst.registry import register, unregister

CLEARANCE = "clearance(self, granted)"


class GuardedFlyToExecutor(FlyToExecutor):
    """A fly-to that fails at its start without the operator's clearance."""

    def on_start(self) -> None:
        if not self.ctx.layer.beliefs.holds(CLEARANCE):
            raise ValueError(f"no clearance: {CLEARANCE} does not hold")


class GuardedFlyTo(FlyTo):
    name = "guarded-fly-to"
    doc = "A fly-to that needs the operator's clearance (a test leaf)."
    executor = GuardedFlyToExecutor


@contextmanager
def guarded_leaf() -> Iterator[GuardedFlyTo]:
    """``guarded-fly-to`` registered for the duration."""
    leaf = register(GuardedFlyTo())
    try:
        yield leaf  # type: ignore[misc]
    finally:
        unregister(leaf.name)
