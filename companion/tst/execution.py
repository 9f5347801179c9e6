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

Failing safely (ours; seed 000 leaves a failure to the platform):

* a node with ``retries: N`` that fails (not one that is aborted) is started again, up to N times, before
  its failure ends its parent; each new attempt is a ``node_retry`` event and starts
  :data:`RETRY_DELAY_S` later (the vehicle holds meanwhile; the nodes below it get their own retries
  back);
* once the mission has failed or was aborted, the mission's ``on_failure`` policy is applied once
  (:meth:`TstExecutionSystem.apply_policy`): ``hover`` leaves the vehicle to the executive layer's default
  KEEP_HOVERING, ``land`` asks for LAND and ``rtl`` for RTL, as the mission requester (an operator's or
  the safety monitor's behavior keeps its priority: the request is then refused, and the event says why).

Following it: every mark is also an event of :attr:`TstExecutionSystem.events` (an
:class:`~companion.tst.events.EventStream`): ``mission_started``, ``node_started`` / ``control_started``,
``node_waiting`` (with what it waits for), ``node_finished`` (state, reason), ``control_finished``,
``node_retry``, ``mission_finished``, ``on_failure``; a node that waits says why in :meth:`status`.

The system is ticked by the executive layer's monitor cycle (autopilot time); requests come from the
HTTP surface. One lock orders both.
"""

from __future__ import annotations

import logging
import re
import threading
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from companion.tst.conditions import parse_condition
from companion.tst.events import EventStream
from companion.tst.executor import ExecContext, TstExecutor
from companion.tst.plan import NodePlan
from companion.tst.registry import leaf_type
from companion.tst.spec import FAILURE_POLICIES, Mission
from companion.tst.status import (
    ExecutionRequestError,
    ExecutorLifecycle,
    NodeExecutionStatus,
    control_execution_info,
)
from companion.tst.tree import ControlType, TstNode

log = logging.getLogger(__name__)

#: how long a failed node waits before its next attempt (autopilot seconds)
RETRY_DELAY_S = 1.0


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
        self._reported = False

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
        self.ctx.mark("control_started", node=self.node.id, task=self.node.type)
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
            self._report()
            return self.status
        self._settle()
        return self.status

    def _report(self) -> None:
        """The event of this node's end (once)."""
        if self.finished and not self._reported:
            self._reported = True
            self.ctx.mark("control_finished", node=self.node.id, state=self.status.state,
                          reason=self.status.fail_reason)

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
            self.system.reset_attempts(self.node.children[0])
            self._spawn(self.node.children[0], bindings)
        return holds

    def tick(self, now_s: float) -> None:
        if self.finished:
            return
        for run in list(self.children):
            if not self.system.start_if_due(run, now_s) and not run.finished:
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
        self._move_on()
        self._report()

    def _retry_failed(self) -> Run | None:
        """A failed child is replaced by a new run while its retries last (started by :meth:`tick` after
        :data:`RETRY_DELAY_S`); the failed child left, if any."""
        failed = next((r for r in self.children if r.finished and not r.status.succeeded), None)
        if failed is None or failed.status.aborted or self.status.aborted:
            return failed
        again = self.system.retry(failed)
        if again is None:
            return failed
        self.children[self.children.index(failed)] = again
        return None

    def _move_on(self) -> None:
        if self.finished:
            return
        if self.status.paused and not any(r.status.paused for r in self.running()):
            self.lifecycle.continue_requested()
        failed = self._retry_failed()
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
        self._report()
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
        self._sink = mark or (lambda event, **fields: None)
        #: (node id, seconds of plan left from it) -> why the vehicle is not ready, or None
        self.readiness = readiness
        self.mission: Mission | None = None
        self.plans: dict[str, NodePlan] = {}
        self.root_run: Run | None = None
        self.runs: dict[str, Run] = {}  # the latest run of each node (a WHILE body runs again)
        #: what happened, for followers (module docstring)
        self.events = EventStream(getattr(layer, "now", None))
        self.attempts: dict[str, int] = {}  # node id -> attempts started (absent: 1)
        self.waiting: dict[str, str] = {}  # node id -> the coordinator's reason it waits
        self.retry_due: dict[str, float] = {}  # node id -> when its new attempt starts (autopilot s)
        #: the failure policy applied at the last failed or aborted end (None: not applied yet)
        self.failure_policy: dict[str, Any] | None = None
        self._ended = False
        self._lock = threading.RLock()

    def mark(self, event: str, **fields: Any) -> None:
        """One event: to the followers' stream and to the flight log."""
        node = fields.get("node")
        if event == "node_waiting" and node is not None:
            self.waiting[str(node)] = str(fields.get("reason", ""))
            fields = {**fields, "waiting_for": self.explain_wait(str(fields.get("reason", "")))}
        elif node is not None:
            self.waiting.pop(str(node), None)
        self.events.record(event, **fields)
        self._sink(event, **fields)

    # --- the mission --------------------------------------------------------------------------------------
    def load(self, mission: Mission, plans: dict[str, NodePlan]) -> None:
        with self._lock:
            if self.running:
                raise ExecutionRequestError("a mission is running: abort it first")
            self.mission, self.plans = mission, dict(plans)
            self.root_run, self.runs, self.attempts, self.waiting, self.retry_due = None, {}, {}, {}, {}
            self.failure_policy, self._ended = None, False
            self.mark("mission_loaded", mission=mission.name, nodes=[n.id for n in mission.root.iter()],
                      on_failure=mission.on_failure)

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

    # --- retries ------------------------------------------------------------------------------------------
    def retry(self, failed: Run) -> Run | None:
        """A new run of a failed (not aborted) node while its ``retries`` last, else None."""
        node = failed.node
        key = node.id or ""
        done = self.attempts.get(key, 1)
        if failed.status.aborted or done > node.retries:
            return None
        self.attempts[key] = done + 1
        self.reset_attempts(node, keep_self=True)
        self.retry_due[key] = failed.ctx.now() + RETRY_DELAY_S
        self.mark("node_retry", node=node.id, attempt=done + 1, attempts=node.retries + 1,
                  reason=failed.status.fail_reason, in_s=RETRY_DELAY_S)
        log.info("%s failed (%s): attempt %d of %d in %g s", node.id, failed.status.fail_reason, done + 1,
                 node.retries + 1, RETRY_DELAY_S)
        return self.make_run(node, failed.ctx)

    def start_if_due(self, run: Run, now_s: float) -> bool:
        """Start a retried run once its delay has passed; True while it still waits to be started."""
        key = run.node.id or ""
        if key not in self.retry_due or run.status.active or run.status.finished:
            return False
        if now_s < self.retry_due[key]:
            return True
        del self.retry_due[key]
        try:
            run.start()
        except ExecutionRequestError as exc:
            log.warning("%s could not start again: %s", key, exc)
        return False

    def reset_attempts(self, node: TstNode, keep_self: bool = False) -> None:
        """A new execution of ``node``'s subtree: the nodes below it get their retries back."""
        for n in node.iter():
            if not (keep_self and n is node):
                self.attempts.pop(n.id or "", None)

    # --- Fig. 3 requests (HTTP) ---------------------------------------------------------------------------
    def start(self, break_in_control: str = "joystick") -> NodeExecutionStatus:
        with self._lock:
            if self.mission is None:
                raise ExecutionRequestError("no mission loaded")
            if self.running:
                raise ExecutionRequestError("the mission is already running")
            ctx = ExecContext(self.layer, self.mark, break_in_control, readiness=self._ready)
            self.runs, self.attempts, self.waiting, self.retry_due = {}, {}, {}, {}
            self.failure_policy, self._ended = None, False
            self.root_run = self.make_run(self.mission.root, ctx)
            self.mark("mission_started", mission=self.mission.name, on_failure=self.mission.on_failure)
            self.root_run.start()
            self._after()
            return self.root_run.status

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

    def abort(self, reason: str = "operator", policy: str | None = None) -> NodeExecutionStatus:
        """Abort the mission; then apply ``policy`` (None: the mission's ``on_failure``)."""
        if policy is not None and policy not in FAILURE_POLICIES:
            raise ExecutionRequestError(f"on_failure: one of {', '.join(FAILURE_POLICIES)}, got {policy!r}")
        def abort(r: Run) -> NodeExecutionStatus:
            if not r.status.active:  # a retry not started yet
                r.lifecycle.prepare()
            return r.abort(reason)
        return self._request(abort, policy)

    def _request(self, fn: Callable[[Run], NodeExecutionStatus], policy: str | None = None
                 ) -> NodeExecutionStatus:
        with self._lock:
            if not self.running or self.root_run is None:
                raise ExecutionRequestError("no mission is running")
            status = fn(self.root_run)
            self._after(policy)
            return status

    def tick(self, now_s: float) -> None:
        with self._lock:
            root = self.root_run
            if self.running and root is not None:
                if not self.start_if_due(root, now_s):
                    root.tick(now_s)
                self._after()

    def _after(self, policy: str | None = None) -> None:
        """Once the root finished: a retry of the root if it asked for one, else the mission's end (its
        event, and the failure policy when it did not succeed)."""
        root = self.root_run
        if root is not None and root.finished and not self._ended:
            again = self.retry(root)
            if again is not None:
                self.root_run = again  # started by tick() after the delay
                return
        if root is None or not root.finished or self._ended:
            return
        self._ended = True
        s = root.status
        self.mark("mission_finished", state=s.state, reason=s.fail_reason)
        log.info("mission %s %s %s", self.mission.name if self.mission else "", s.state, s.fail_reason)
        if not s.succeeded:
            self.apply_policy(policy or (self.mission.on_failure if self.mission else "hover"), s.fail_reason)

    def apply_policy(self, policy: str, cause: str) -> dict[str, Any]:
        """What a failure or an abort does (module docstring); the record is also an ``on_failure`` event."""
        record: dict[str, Any] = {"policy": policy, "cause": cause}
        if policy == "hover":
            record.update(applied=True, behavior="KEEP_HOVERING",
                          reason="the executive layer's default KEEP_HOVERING holds the vehicle")
        else:
            behavior = "LAND" if policy == "land" else "RTL"
            result = self.layer.coordinator.activate(behavior, "mission")
            record.update(applied=result.accepted, behavior=behavior, activation_id=result.activation_id,
                          reason=result.reason)
            if not result.accepted:
                log.warning("on_failure %s: %s refused: %s", policy, behavior, result.reason)
        self.failure_policy = record
        self.mark("on_failure", **record)
        return record

    # --- what a waiting node waits for ------------------------------------------------------------------
    def explain_wait(self, reason: str) -> str:
        """The coordinator's reason for a wait, in the operator's words, with why a behavior it needs is not
        active (e.g. "waiting: TAKE_OFF needs SELF_LOCALIZE active first (SELF_LOCALIZE: the autopilot's
        position estimate is not healthy ...)")."""
        text = reason.removeprefix("precedence: ").removeprefix("situation: ")
        m = re.match(r"precedence: \S+ needs (.+) active first", reason)
        if m:
            controllers = getattr(self.layer.coordinator, "controllers", {})
            why = []
            for name in (x.strip() for x in m.group(1).split(",")):
                ctrl = controllers.get(name)
                if ctrl is None:
                    continue
                try:
                    blocked = ctrl.check_activation({})
                except Exception:  # a controller that cannot answer without parameters
                    blocked = None
                if blocked:
                    why.append(f"{name}: {blocked}")
            if why:
                text += f" ({'; '.join(why)})"
        return f"waiting: {text}"

    def failed_node(self) -> str | None:
        """The deepest node of the last execution that failed or was aborted (None: none did)."""
        with self._lock:
            if self.mission is None:
                return None
            best: tuple[int, str] | None = None
            for n in self.mission.root.iter():
                run = self.runs.get(n.id or "")
                if run is not None and run.finished and not run.status.succeeded:
                    depth = n.depth()
                    if best is None or depth > best[0]:
                        best = (depth, str(n.id))
            return best[1] if best else None

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
                    "active_node": self.active_node(),
                    "waiting": [{"node": k, "for": self.explain_wait(v)} for k, v in self.waiting.items()
                                if self._is_waiting(k)],
                    "on_failure": self.mission.on_failure, "failure_policy": self._policy_view(),
                    "failed_node": self.failed_node() if root is not None and root.finished else None,
                    "events_seq": self.events.last_seq, "tree": self._node(self.mission.root)}

    def _is_waiting(self, node_id: str) -> bool:
        run = self.runs.get(node_id)
        return run is not None and run.status.waiting

    def _policy_view(self) -> dict[str, Any] | None:
        """The applied failure policy with its behavior's outcome so far (active, or how it ended)."""
        if self.failure_policy is None:
            return None
        out = dict(self.failure_policy)
        aid = out.get("activation_id")
        if aid:
            coordinator = self.layer.coordinator
            ended = next((e for e in reversed(coordinator.ended) if e.activation_id == aid), None)
            out["outcome"] = ended.cause.value if ended is not None else "active"
        return out

    def _node(self, node: TstNode) -> dict[str, Any]:
        run = self.runs.get(node.id or "")
        out: dict[str, Any] = {"id": node.id, "type": node.type}
        if node.condition is not None:
            out["condition"] = node.condition
        if node.retries:
            out["retries"] = node.retries
            out["attempt"] = self.attempts.get(node.id or "", 1) if run is not None else 0
        if run is not None and not run.status.active and (node.id or "") in self.retry_due:
            out["retry_at"] = round(self.retry_due[node.id or ""], 3)  # the next attempt (autopilot s)
        if run is not None and run.status.waiting and (node.id or "") in self.waiting:
            out["waiting_for"] = self.explain_wait(self.waiting[node.id or ""])
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
