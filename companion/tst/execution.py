"""The TST execution system (seed 000 Sec. III, Fig. 2-5): runs a delegated tree on this platform.

Leaves run as their task type's executor (:mod:`companion.tst.leaves`); control nodes are run here:

* ``S`` starts its children one after the other; a child that fails or is aborted ends the sequence
  the same way;
* ``C`` starts all its children together and ends when all have (two flight behaviors exclude each other
  in the behavior coordinator, so C suits a flight task beside non-flight ones);
* ``IF`` evaluates its condition (a belief query, :mod:`.conditions`) when it starts and runs the
  *then* or the *else* child (none: it succeeds); the first solution's bindings (``?x``) are visible
  to the nodes below it;
* ``WHILE`` evaluates its condition before each iteration and runs its body while it holds; the
  condition is also watched *during* the body: once it no longer holds, the body is enoughed if it can
  be (a scan "until a person is seen" ends when the camera sees one), else it runs to its end.

Requests (Fig. 3: abort, pause, continue, enough) are given to the root and passed down to the running
children: a control node allows one exactly when every running child does
(:func:`~.status.control_execution_info`). An enough ends the running leaf as done and the sequence goes
on with the next node (Sec. VII: the scan is enoughed, the mission flies on to the fly-to).

The system is ticked by the executive layer's monitor cycle (autopilot time); requests come from the
HTTP surface. One lock orders both.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from companion.tst.conditions import parse_condition
from companion.tst.executor import ExecContext, TstExecutor
from companion.tst.plan import NodePlan
from companion.tst.registry import leaf_type
from companion.tst.spec import Mission
from companion.tst.status import (
    ExecutionRequestError,
    ExecutorLifecycle,
    NodeExecutionStatus,
    control_execution_info,
)
from companion.tst.tree import ControlType, TstNode

log = logging.getLogger(__name__)


class ControlRun:
    """One execution of an S, C, IF or WHILE node (see module docstring)."""

    def __init__(self, node: TstNode, system: TstExecutionSystem, ctx: ExecContext) -> None:
        self.node = node
        self.system = system
        self.ctx = ctx
        self.children: list[Run] = []
        self.lifecycle = ExecutorLifecycle(self._info, node.id or node.type)
        self.iteration = 0
        self.branch: str | None = None
        self._index = 0

    def _info(self) -> Any:
        return control_execution_info(r.lifecycle.info for r in self.running())

    @property
    def status(self) -> NodeExecutionStatus:
        return self.lifecycle.status

    @property
    def finished(self) -> bool:
        return self.lifecycle.status.finished

    def running(self) -> list[Run]:
        return [r for r in self.children if r.status.executing or r.status.waiting]

    # --- lifecycle -----------------------------------------------------------------------------------------
    def start(self) -> NodeExecutionStatus:
        self.lifecycle.prepare()
        self.lifecycle.start()
        kind = self.node.control
        if kind is ControlType.C:
            for child in self.node.children:
                self._spawn(child)
        elif kind is ControlType.S:
            self._next_in_sequence()
        elif kind is ControlType.IF:
            holds, bindings = self._evaluate()
            self.branch = "then" if holds else "else"
            taken = self.node.then if holds else self.node.else_
            if taken is not None:
                self._spawn(taken, bindings)
        elif kind is ControlType.WHILE and not self._iterate():
            self.lifecycle.succeed()  # the condition does not hold: nothing to repeat
            return self.status
        self._settle()
        return self.status

    def _evaluate(self) -> tuple[bool, dict[str, Any]]:
        holds, bindings = parse_condition(self.node.condition or "").evaluate(self.ctx.layer.beliefs)
        self.ctx.mark("condition", node=self.node.id, condition=self.node.condition, holds=holds,
                      bindings={k: str(v) for k, v in bindings.items()})
        return holds, bindings

    def _spawn(self, node: TstNode, bindings: dict[str, Any] | None = None) -> Run:
        ctx = replace(self.ctx, bindings={**self.ctx.bindings, **(bindings or {})})
        run = self.system.make_run(node, ctx)
        self.children.append(run)
        try:
            run.start()
        except ExecutionRequestError as exc:
            log.warning("%s could not start: %s", node.id, exc)
        return run

    def _next_in_sequence(self) -> None:
        while self._index < len(self.node.children):
            run = self._spawn(self.node.children[self._index])
            if not (run.finished and run.status.succeeded):
                return
            self._index += 1

    def _iterate(self) -> bool:
        """The next iteration if the condition holds (True: a body was started)."""
        holds, bindings = self._evaluate()
        if holds:
            self.iteration += 1
            self.children = []
            self._spawn(self.node.children[0], bindings)
        return holds

    def tick(self, now_s: float) -> None:
        if self.finished:
            return
        for run in list(self.children):
            if not run.finished:
                run.tick(now_s)
        if self.node.control is ControlType.WHILE and self.children and not self.children[-1].finished:
            body = self.children[-1]
            holds, _ = parse_condition(self.node.condition or "").evaluate(self.ctx.layer.beliefs)
            if not holds and body.lifecycle.info.can_be_enoughed and body.status.executing:
                self.ctx.mark("condition", node=self.node.id, condition=self.node.condition, holds=False)
                body.enough_requested()
        self._settle()

    def _settle(self) -> None:
        """Move on once the running children finished: next child, next iteration, or this node's end."""
        if self.finished:
            return
        if self.status.paused and not any(r.status.paused for r in self.running()):
            self.lifecycle.continue_requested()
        failed = next((r for r in self.children if r.finished and not r.status.succeeded), None)
        if failed is not None:
            reason = f"{failed.node.id}: {failed.status.fail_reason}"
            if self.status.paused:
                self.lifecycle.continue_requested()
            for r in self.running():
                _quietly(r.abort, f"{self.node.id} ended")
            if failed.status.aborted:
                self.lifecycle.abort(reason)
            else:
                self.lifecycle.fail(reason)
            return
        if any(not r.finished for r in self.children):
            return
        kind = self.node.control
        # the current child of a sequence just succeeded
        if kind is ControlType.S and self._index < len(self.node.children):
            self._index += 1
            self._next_in_sequence()
            if self._index < len(self.node.children):
                return
        elif kind is ControlType.WHILE and self.children and self._iterate():
            return  # the next iteration runs (a body that ended at once is looked at next tick)
        self.lifecycle.succeed()

    # --- requests, passed to the running children ----------------------------------------------------------
    def pause_requested(self, control: str | None = None) -> NodeExecutionStatus:
        self.lifecycle.pause_requested()
        for r in self.running():
            r.pause_requested(control)
        return self.status

    def continue_requested(self) -> NodeExecutionStatus:
        self.lifecycle.continue_requested()
        for r in self.running():
            if r.status.paused:
                r.continue_requested()
        return self.status

    def enough_requested(self) -> NodeExecutionStatus:
        running = self.running()
        if not running or not self._info().can_be_enoughed:
            raise ExecutionRequestError(f"{self.node.id}: enough refused: the running task cannot be "
                                        "enoughed")
        for r in running:
            r.enough_requested()
        self._settle()
        return self.status

    def abort(self, reason: str = "") -> NodeExecutionStatus:
        if self.status.paused:
            self.lifecycle.continue_requested()
        self.lifecycle.abort(reason)
        for r in self.running():
            _quietly(r.abort, reason)
        return self.status

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.node.control is ControlType.WHILE:
            out["iteration"] = self.iteration
        if self.branch is not None:
            out["branch"] = self.branch
        return out


Run = ControlRun | TstExecutor


def _subtree_s(node: TstNode, plans: dict[str, NodePlan]) -> float:
    """Expected seconds of a subtree: S and WHILE (one pass) sum, C and IF take the longest child."""
    if not node.is_control:
        plan = plans.get(str(node.id))
        return (plan.expected_s or 0.0) if plan is not None else 0.0
    kids = [_subtree_s(c, plans) for c in node.children if c.parent is node]
    if node.control in (ControlType.S, ControlType.WHILE):
        return sum(kids)
    return max(kids, default=0.0)


def _quietly(fn: Callable[..., Any], *args: Any) -> None:
    try:
        fn(*args)
    except ExecutionRequestError as exc:
        log.info("%s", exc)


class TstExecutionSystem:
    """Runs one delegated mission at a time on the executive layer (see module docstring)."""

    def __init__(self, layer: Any, mark: Callable[..., None] | None = None,
                 readiness: Callable[[str, float], str | None] | None = None) -> None:
        self.layer = layer
        self.mark = mark or (lambda event, **fields: None)
        #: (node id, seconds of plan left from it) -> why the vehicle is not ready, or None
        self.readiness = readiness
        self.mission: Mission | None = None
        self.plans: dict[str, NodePlan] = {}
        self.root_run: Run | None = None
        self.runs: dict[str, Run] = {}  # the latest run of each node (a WHILE body runs again)
        self._lock = threading.RLock()

    # --- the mission --------------------------------------------------------------------------------------
    def load(self, mission: Mission, plans: dict[str, NodePlan]) -> None:
        with self._lock:
            if self.running:
                raise ExecutionRequestError("a mission is running: abort it first")
            self.mission, self.plans = mission, dict(plans)
            self.root_run, self.runs = None, {}
            self.mark("mission_loaded", mission=mission.name, nodes=[n.id for n in mission.root.iter()])

    @property
    def running(self) -> bool:
        return self.root_run is not None and not self.root_run.finished

    def root_status(self) -> NodeExecutionStatus | None:
        """The root's Fig. 5 status (None before a start): what :meth:`status` reports as state and
        fail_reason, without building the tree view."""
        with self._lock:
            return self.root_run.status if self.root_run is not None else None

    def make_run(self, node: TstNode, ctx: ExecContext) -> Run:
        if node.is_control:
            run: Run = ControlRun(node, self, ctx)
        else:
            plan = self.plans.get(node.id or "") or NodePlan(node.id or "", node.type)
            run = leaf_type(node.type).make_executor(node, plan, ctx)
        self.runs[node.id or ""] = run
        return run

    # --- Fig. 3 requests (HTTP) ---------------------------------------------------------------------------
    def start(self, break_in_control: str = "joystick") -> NodeExecutionStatus:
        with self._lock:
            if self.mission is None:
                raise ExecutionRequestError("no mission loaded")
            if self.running:
                raise ExecutionRequestError("the mission is already running")
            ctx = ExecContext(self.layer, self.mark, break_in_control, readiness=self._ready)
            self.runs = {}
            self.root_run = self.make_run(self.mission.root, ctx)
            self.mark("mission_started", mission=self.mission.name)
            return self.root_run.start()

    def _ready(self, node: TstNode) -> str | None:
        if self.readiness is None:
            return None
        return self.readiness(str(node.id), self.seconds_left(node))

    def seconds_left(self, node: TstNode) -> float:
        """The plan's expected seconds from ``node``'s start to the mission's end: the node, and after it
        what its S ancestors still have to run (a WHILE counts the rest of its pass: its passes have no
        bound; a repeated scan counts one pass)."""
        total = _subtree_s(node, self.plans)
        child = node
        parent = node.parent
        while parent is not None:
            if parent.control is ControlType.S:
                kids = list(parent.children)
                total += sum(_subtree_s(k, self.plans) for k in kids[kids.index(child) + 1:])
            child, parent = parent, parent.parent
        return total

    def pause(self, control: str | None = None) -> NodeExecutionStatus:
        return self._request(lambda r: r.pause_requested(control))

    def continue_(self) -> NodeExecutionStatus:
        return self._request(lambda r: r.continue_requested())

    def enough(self) -> NodeExecutionStatus:
        return self._request(lambda r: r.enough_requested())

    def abort(self, reason: str = "operator") -> NodeExecutionStatus:
        return self._request(lambda r: r.abort(reason))

    def _request(self, fn: Callable[[Run], NodeExecutionStatus]) -> NodeExecutionStatus:
        with self._lock:
            if not self.running or self.root_run is None:
                raise ExecutionRequestError("no mission is running")
            return fn(self.root_run)

    def tick(self, now_s: float) -> None:
        with self._lock:
            if self.running and self.root_run is not None:
                self.root_run.tick(now_s)
                if self.root_run.finished:
                    s = self.root_run.status
                    self.mark("mission_finished", state=s.state, reason=s.fail_reason)
                    log.info("mission %s %s %s", self.mission.name if self.mission else "", s.state,
                             s.fail_reason)

    # --- views ----------------------------------------------------------------------------------------------
    def active_node(self) -> str | None:
        """The deepest running node (a leaf), for the flight log and the operator."""
        with self._lock:
            run = self.root_run
            while isinstance(run, ControlRun):
                inner = run.running()
                if not inner:
                    return run.node.id
                run = inner[-1]
            return run.node.id if run is not None and not run.finished else None

    def status(self) -> dict[str, Any]:
        with self._lock:
            if self.mission is None:
                return {"mission": None, "state": "none", "tree": None}
            root = self.root_run
            return {"mission": self.mission.name,
                    "state": root.status.state if root is not None else "loaded",
                    "fail_reason": root.status.fail_reason if root is not None else "",
                    "active_node": self.active_node(), "tree": self._node(self.mission.root)}

    def _node(self, node: TstNode) -> dict[str, Any]:
        run = self.runs.get(node.id or "")
        out: dict[str, Any] = {"id": node.id, "type": node.type}
        if node.condition is not None:
            out["condition"] = node.condition
        if not node.is_control:
            out["params"] = node.to_dict().get("params", {})
            plan = self.plans.get(node.id or "")
            if plan is not None:
                out["plan"] = plan.to_dict()
        info = run.lifecycle.info if run is not None else None
        out["info"] = info.to_dict() if info is not None else None
        out["status"] = run.status.to_dict() if run is not None else NodeExecutionStatus().to_dict()
        out["state"] = run.status.state if run is not None else "idle"
        if run is not None:
            out["progress"] = run.to_dict()
        if node.is_control:
            out["children"] = [self._node(c) for c in node.children]
        elif node.children:
            out["expansion"] = len(node.children)
        return out
