"""The Fig. 5 status of a control node derived from its children's (seed 000 Sec. III, Fig. 5).

Control nodes have no platform activity of their own: "Platforms can share implementations of some
executors, such as those corresponding to general control structures" (Sec. III). Their status is a
summary of their children's, for the operator (``GET /mission``) and the execution system:

* ``S`` (and ``IF``, given the one branch taken): it fails or is aborted as soon as a child does (the
  rest of the sequence will not run), succeeds when every child succeeded, and otherwise is active once a
  child is, executing while any child executes or between two children, waiting while its running child
  waits, paused while its running child is paused;
* ``C``: finished when every child has finished: succeeded if all succeeded, else aborted if one was
  aborted, else failed; before that it is executing while any child runs (or some already finished),
  waiting while running children only wait, paused while every executing child is paused.

``WHILE`` repeats its body, so its children's status does not tell whether it has finished; the
execution system keeps a lifecycle (:class:`~companion.tst.status.ExecutorLifecycle`) for it and may use
the ``S`` rule for the current iteration. The Fig. 4 flags of control nodes are in
:func:`companion.tst.status.control_execution_info`.
"""

from __future__ import annotations

from collections.abc import Sequence

from companion.tst.status import NodeExecutionStatus
from companion.tst.tree import ControlType, control_type


def derived_status(node_type: str, children: Sequence[NodeExecutionStatus]) -> NodeExecutionStatus:
    """The Fig. 5 status of an ``S``, ``C`` or ``IF`` node whose (taken) children have ``children``."""
    control = control_type(node_type)
    if control in (ControlType.S, ControlType.IF):
        return _sequence(children)
    if control is ControlType.C:
        return _concurrent(children)
    raise ValueError(f"no derived status for a {node_type} node (only S, C and IF)")


def _failure(children: Sequence[NodeExecutionStatus]) -> NodeExecutionStatus | None:
    for i, c in enumerate(children):
        if c.finished and not c.succeeded:
            return NodeExecutionStatus(active=any(x.active for x in children), finished=True,
                                       aborted=c.aborted, fail_reason=f"child {i}: {c.fail_reason}")
    return None


def _running(children: Sequence[NodeExecutionStatus], started: bool) -> NodeExecutionStatus:
    """Not finished: the flags of the children that are running."""
    executing = [c for c in children if c.executing]
    waiting = any(c.waiting for c in children)
    active = started or any(c.active for c in children)
    between = not executing and not waiting and any(c.finished for c in children)
    return NodeExecutionStatus(active=active, waiting=waiting and not executing and not between,
                               executing=bool(executing) or between,
                               paused=bool(executing) and all(c.paused for c in executing))


def _sequence(children: Sequence[NodeExecutionStatus]) -> NodeExecutionStatus:
    failed = _failure(children)
    if failed is not None:
        return failed
    if children and all(c.finished for c in children):
        return NodeExecutionStatus(active=True, finished=True, succeeded=True)
    return _running(children, started=any(c.finished for c in children))


def _concurrent(children: Sequence[NodeExecutionStatus]) -> NodeExecutionStatus:
    if children and all(c.finished for c in children):
        if all(c.succeeded for c in children):
            return NodeExecutionStatus(active=True, finished=True, succeeded=True)
        aborted = [i for i, c in enumerate(children) if c.aborted]
        i = aborted[0] if aborted else next(i for i, c in enumerate(children) if not c.succeeded)
        return NodeExecutionStatus(active=True, finished=True, aborted=bool(aborted),
                                   fail_reason=f"child {i}: {children[i].fail_reason}")
    return _running(children, started=any(c.finished for c in children))
