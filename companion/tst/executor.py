"""The platform-specific TST executor of a leaf (seed 000 Sec. III-A, Fig. 3-5) over the behavior coordinator.

A :class:`TstExecutor` runs one leaf of a delegated tree. It never talks to the queue or the link: it is
the *mission requester* of the behavior coordinator (seed 001), and the behaviors put the flight
commands of seed 000 Fig. 11-14 on the queue. Its Fig. 5 status is an
:class:`~companion.tst.status.ExecutorLifecycle` with the task type's Fig. 4 flags; the requests map
to behaviors:

=====================  ===========================================================================
``start()``            activate the task's behavior (``activation()``), mission requester; a
                       rejection fails the node with the coordinator's reason
``pause_requested()``  the operator's break-in: REQUEST_OPERATOR_ASSISTANCE with ``control:
                       joystick`` (or ``hover``), operator requester: the queue pauses the running
                       command and the operator's stick (``ext_vel``) flies the vehicle
``continue_requested`` inhibit that break-in: the paused command resumes where it stopped
``enough_requested()`` end the task as done: the break-in (if any) and the behavior are inhibited,
                       the node succeeds, KEEP_HOVERING holds until the next node
``abort()``            the same, but the node is aborted
=====================  ===========================================================================

``tick(now)`` follows the behavior: ``goal_achieved`` succeeds the node; ``time_out``,
``wrong_progress`` or an interruption it did not ask for (an emergency LAND) fail it with the cause. A
break-in the operator ends with ``user_confirm`` continues the node.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from companion.tst.plan import NodePlan
from companion.tst.status import (
    ExecutionRequestError,
    ExecutorLifecycle,
    NodeExecutionStatus,
    execution_info,
)

if TYPE_CHECKING:
    from companion.behaviors.coordinator import BehaviorCoordinator, Ended
    from companion.behaviors.system import ExecutiveLayer
    from companion.tst.tree import TstNode

log = logging.getLogger(__name__)

BREAK_IN = "REQUEST_OPERATOR_ASSISTANCE"
#: how long a node waits for its behavior's precedence or situation (seconds of autopilot time)
WAIT_LIMIT_S = 15.0


def _transient(reason: str) -> bool:
    """A rejection that time may lift: a needed behavior not active yet (precedence), or the situation
    (the belief memory still says taking_off a tick after the take-off ended)."""
    return reason.startswith(("precedence:", "situation:"))


@dataclass
class ExecContext:
    """What executors use: the executive layer, the mission's event sink, the condition bindings."""

    layer: ExecutiveLayer
    mark: Callable[..., None] = lambda event, **fields: None
    break_in_control: str = "joystick"
    bindings: dict[str, Any] = field(default_factory=dict)
    #: the re-check before a node starts (Fig. 3 prepare()): why the vehicle is not ready to run ``node``
    #: and the rest of the plan after it (link, estimate, battery), or None
    readiness: Callable[[TstNode], str | None] = lambda node: None

    @property
    def coordinator(self) -> BehaviorCoordinator:
        return self.layer.coordinator

    def now(self) -> float:
        return self.layer.now()


class TstExecutor(ABC):
    """One leaf's executor (see module docstring). Subclasses give :meth:`activation`; the leaf task type
    (:class:`~companion.tst.leaves.base.LeafType`) names its executor class."""

    def __init__(self, node: TstNode, plan: NodePlan, ctx: ExecContext) -> None:
        self.task = node.type
        self.node = node
        self.plan = plan
        self.ctx = ctx
        self.lifecycle = ExecutorLifecycle(execution_info(node.type), node.id or node.type)
        self.activation_id: str | None = None
        self.behavior: str | None = None
        self.break_in_id: str | None = None
        self._own_ends: set[str] = set()  # activations we ended ourselves (enough, abort, continue)
        self._waiting_since = 0.0

    # --- what a subclass says -------------------------------------------------------------------------
    @abstractmethod
    def activation(self) -> str:
        """The behavior activation (text form) that performs the task."""

    def progress(self) -> dict[str, Any]:
        return {}

    def on_start(self) -> None:
        """Before the behavior is asked for (e.g. the camera labels its results); by default nothing."""
        return None

    def on_end(self) -> None:
        """After the node finished, whichever way; by default nothing."""
        return None

    # --- Fig. 3 ------------------------------------------------------------------------------------------
    @property
    def status(self) -> NodeExecutionStatus:
        return self.lifecycle.status

    @property
    def finished(self) -> bool:
        return self.lifecycle.status.finished

    def prepare(self) -> NodeExecutionStatus:
        return self.lifecycle.prepare()

    def not_ready(self) -> str | None:
        """Fig. 3 prepare()'s re-check: why the vehicle cannot start this node now (the context's
        ``readiness``: link, estimate, battery against the rest of the plan), or None."""
        return self.ctx.readiness(self.node)

    def start(self) -> NodeExecutionStatus:
        """Fig. 3 start(): the behavior is asked for. A rejection for precedence (a behavior it needs is
        not active yet, e.g. SELF_LOCALIZE before the autopilot's estimate is healthy) or for its
        situation (the beliefs lag the vehicle by an update) is a *wait condition*: the node is
        ``waiting`` (Fig. 5) and asks again every tick, for up to :data:`WAIT_LIMIT_S`; any other
        rejection (a higher-priority behavior active, a bad request) fails it with the reason."""
        if not self.lifecycle.status.active:
            self.prepare()
        why = self.not_ready()
        if why is not None:
            self.lifecycle.start()
            self._fail(f"not ready: {why}")
            return self.status
        try:
            self.on_start()
            text = self.activation()
        except ValueError as exc:
            self.lifecycle.start()
            self._fail(str(exc))
            return self.status
        result = self.ctx.coordinator.activate(text, "mission")
        if not result.accepted and _transient(result.reason):
            self.lifecycle.start(wait_conditions_met=False)
            self._waiting_since = self.ctx.now()
            self.ctx.mark("node_waiting", node=self.node.id, reason=result.reason)
            return self.status
        self.lifecycle.start()
        self._accepted(text, result)
        return self.status

    def _accepted(self, text: str, result: Any) -> None:
        if not result.accepted:
            self._fail(f"{text}: {result.reason}")
            return
        self.activation_id, self.behavior = result.activation_id, result.behavior
        self.ctx.mark("node_started", node=self.node.id, task=self.task, activation=self.activation_id)

    def _retry(self, now_s: float) -> None:
        """Waiting: ask again; executing once accepted, failed after :data:`WAIT_LIMIT_S`."""
        text = self.activation()
        result = self.ctx.coordinator.activate(text, "mission")
        if result.accepted:
            self.lifecycle.conditions_met()
            self._accepted(text, result)
        elif not _transient(result.reason) or now_s - self._waiting_since > WAIT_LIMIT_S:
            self._fail(f"{text}: {result.reason}")

    def _ask(self, text: str) -> bool:
        result = self.ctx.coordinator.activate(text, "mission")
        if not result.accepted:
            self._fail(f"{text}: {result.reason}")
            return False
        self.activation_id, self.behavior = result.activation_id, result.behavior
        return True

    def tick(self, now_s: float) -> None:
        if self.status.waiting and not self.finished:
            self._retry(now_s)
        if self.finished or not self.status.executing:
            return
        if self.break_in_id is not None:
            ended = self._ended(self.break_in_id)
            if ended is not None:  # the operator confirmed on the queue: the node goes on
                self.break_in_id = None
                if self.status.paused:
                    self.lifecycle.continue_requested()
                    self.ctx.mark("node_continued", node=self.node.id, by="operator confirmation")
                    self.ctx.mark("break_in_end", node=self.node.id, outcome="continued")
        if self.activation_id is None:
            return
        ended = self._ended(self.activation_id)
        if ended is None or self.activation_id in self._own_ends:
            return
        self.on_behavior_end(ended)

    def on_behavior_end(self, ended: Ended) -> None:
        """The behavior ended by itself: success or failure (override to chain behaviors)."""
        if ended.cause.value == "goal_achieved":
            if self.status.paused:
                self.lifecycle.continue_requested()
            self.lifecycle.succeed()
            self._finished("node_finished", state="succeeded")
        else:
            detail = f": {ended.detail}" if ended.detail else ""
            self._fail(f"{ended.behavior} {ended.cause.value}{detail}")

    # --- the execution system's requests ----------------------------------------------------------------
    def pause_requested(self, control: str | None = None) -> NodeExecutionStatus:
        self.lifecycle.pause_requested()
        control = control or self.ctx.break_in_control
        result = self.ctx.coordinator.activate(f"{BREAK_IN} control: {control}", "operator")
        if not result.accepted:
            self.lifecycle.continue_requested()
            raise ExecutionRequestError(f"{self.node.id}: pause refused: {result.reason}")
        self.break_in_id = result.activation_id
        self.ctx.mark("node_paused", node=self.node.id, control=control, activation=self.break_in_id)
        self.ctx.mark("break_in_start", node=self.node.id, control=control)
        return self.status

    def continue_requested(self) -> NodeExecutionStatus:
        self.lifecycle.continue_requested()
        self._end_break_in("continued")
        self.ctx.mark("node_continued", node=self.node.id, by="continue")
        return self.status

    def enough_requested(self) -> NodeExecutionStatus:
        self.lifecycle.enough_requested()
        self._stop_behavior("enoughed")
        self._finished("node_enoughed")
        return self.status

    def abort(self, reason: str = "") -> NodeExecutionStatus:
        self.lifecycle.abort(reason)
        self._stop_behavior("aborted")
        self._finished("node_aborted", reason=reason)
        return self.status

    # --- helpers ---------------------------------------------------------------------------------------
    def _ended(self, activation_id: str) -> Ended | None:
        ended = self.ctx.coordinator.ended
        return next((e for e in reversed(ended) if e.activation_id == activation_id), None)

    def _end_break_in(self, outcome: str) -> None:
        if self.break_in_id is not None:
            self._own_ends.add(self.break_in_id)
            if self._ended(self.break_in_id) is None:
                self.ctx.coordinator.inhibit(self.break_in_id, "operator")
            self.break_in_id = None
            self.ctx.mark("break_in_end", node=self.node.id, outcome=outcome)

    def _stop_behavior(self, outcome: str) -> None:
        self._end_break_in(outcome)
        if self.activation_id is not None:
            self._own_ends.add(self.activation_id)
            act = self.ctx.coordinator.activation(self.behavior or "")
            if act is not None and act.activation_id == self.activation_id:
                self.ctx.coordinator.inhibit(self.activation_id, "mission")

    def _fail(self, reason: str) -> None:
        self._end_break_in("aborted")
        self.lifecycle.fail(reason)
        self._finished("node_finished", state="failed", reason=reason)

    def _finished(self, event: str, **fields: Any) -> None:
        self.on_end()
        self.ctx.mark(event, node=self.node.id, **fields)
        log.info("%s %s: %s", self.task, self.node.id, self.status.state)

    def to_dict(self) -> dict[str, Any]:
        return {"activation_id": self.activation_id, "behavior": self.behavior, **self.progress()}
