"""Executor execution information (seed 000 Fig. 4), status (Fig. 5) and lifecycle (Fig. 3).

Fig. 4, "Node execution information provided by a TST Executor in form of boolean flags":
``can_be_aborted``, ``can_be_paused``, ``can_be_enoughed``. Each leaf task type holds its LinkQuad
values (Sec. VI) and their source in its module (:mod:`companion.tst.leaves`, ``LeafType.info``):
take-off none (VI-A), fly-to abort and pause (VI-B), scan-ground all three (VI-E); the types the paper
is silent on say why they chose theirs.

Control nodes (S, C, IF, WHILE) take theirs from the children that are running
(:func:`control_execution_info`): a request to a control node is passed to its running children, so it is
allowed exactly when every running child allows it (S and IF and WHILE have one running child, C may have
several). With no child running (before start, between children) a control node can be aborted and nothing
else. This matches Sec. VII: an enough on the running scan ends the scan and the S goes on with fly-to.
Their Fig. 5 status is an :class:`ExecutorLifecycle` of their own, kept by the execution system
(:class:`companion.tst.execution.ControlRun`): executing from their start, paused with their running
children, and finished when the children's outcome ends them (the rules in :mod:`companion.tst.execution`).

Fig. 5, "TST Executor status": ``active``, ``waiting``, ``executing``, ``finished``, ``aborted``,
``succeeded``, ``paused`` and ``fail_reason``. :class:`ExecutorLifecycle` moves between them (Fig. 3):

* ``prepare()`` -> active (or, when the platform is not ready, finished with a fail_reason and not active:
  "active: True if executor exists and has started a successful prepare()");
* ``start()`` -> waiting ("True after start when waiting for all wait conditions to be satisfied") or
  executing; ``conditions_met()`` -> executing ("True when all the wait conditions are met");
* ``succeed()`` (ran its course) -> finished, succeeded; ``fail(reason)`` -> finished, fail_reason;
* ``abort()`` -> finished, aborted ("successfully aborted");
* ``pause_requested()`` -> paused (still executing); ``continue_requested()`` -> not paused;
* ``enough_requested()`` -> finished, succeeded ("enoughing means that the task should stop as enough of it
  has been performed"; a nominal end), also while paused (Fig. 16b: "scan-ground (paused/enoughed)").

A request that the Fig. 4 flags or the state forbid raises :class:`ExecutionRequestError` with the reason and
changes nothing. Abort before the executor executes (prepared or waiting) is always allowed: the flag speaks
of an activity "after it has been initiated" (VI-A); nothing flies yet. Natural success is refused while
paused: a paused task's flight commands are suspended.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, replace
from typing import Any

from companion.tst.registry import leaf_type

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class NodeExecutionInfo:
    """Fig. 4: whether the node's execution can be aborted, paused, or stopped and finished (enoughed)."""

    can_be_aborted: bool = False
    can_be_paused: bool = False
    can_be_enoughed: bool = False

    def to_dict(self) -> dict[str, bool]:
        return asdict(self)


#: A control node with no running child: abortable (nothing runs that forbids it), nothing else.
IDLE_CONTROL_INFO = NodeExecutionInfo(can_be_aborted=True, can_be_paused=False, can_be_enoughed=False)


def execution_info(task_type: str) -> NodeExecutionInfo:
    """The Fig. 4 flags of a leaf task type (KeyError for an unknown type)."""
    return leaf_type(task_type).info


def control_execution_info(running: Iterable[NodeExecutionInfo]) -> NodeExecutionInfo:
    """A control node's Fig. 4 flags from those of its running children: each flag is their conjunction."""
    infos = list(running)
    if not infos:
        return IDLE_CONTROL_INFO
    return NodeExecutionInfo(can_be_aborted=all(i.can_be_aborted for i in infos),
                             can_be_paused=all(i.can_be_paused for i in infos),
                             can_be_enoughed=all(i.can_be_enoughed for i in infos))


@dataclass(frozen=True)
class NodeExecutionStatus:
    """Fig. 5: "All fields except a string fail_reason are boolean flags"."""

    active: bool = False
    waiting: bool = False
    executing: bool = False
    finished: bool = False
    aborted: bool = False
    succeeded: bool = False
    paused: bool = False
    fail_reason: str = ""

    def violations(self) -> list[str]:
        """The consistency rules this combination breaks (empty for every reachable status)."""
        rules = [
            (not self.waiting or self.active, "waiting => active"),
            (not self.executing or self.active, "executing => active"),
            (not (self.waiting and self.executing), "not (waiting and executing)"),
            (not self.paused or self.executing, "paused => executing"),
            (not self.finished or not (self.executing or self.waiting or self.paused),
             "finished => not executing, waiting or paused"),
            (not self.succeeded or (self.finished and not self.aborted and not self.fail_reason),
             "succeeded => finished, not aborted, no fail_reason"),
            (not self.aborted or (self.finished and not self.succeeded),
             "aborted => finished, not succeeded"),
            (not (self.finished and not self.succeeded) or bool(self.fail_reason),
             "finished and not succeeded => fail_reason"),
            (not self.fail_reason or self.finished, "fail_reason => finished"),
        ]
        return [text for ok, text in rules if not ok]

    @property
    def state(self) -> str:
        """One word: idle, prepared, waiting, executing, paused, succeeded, aborted or failed."""
        if self.finished:
            return "succeeded" if self.succeeded else "aborted" if self.aborted else "failed"
        if self.paused:
            return "paused"
        if self.executing:
            return "executing"
        if self.waiting:
            return "waiting"
        return "prepared" if self.active else "idle"

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


class ExecutionRequestError(RuntimeError):
    """A lifecycle call or request refused by the Fig. 4 flags or the current Fig. 5 status."""

    def __init__(self, reason: str) -> None:
        self.reason = reason
        super().__init__(reason)


class ExecutorLifecycle:
    """The Fig. 3 lifecycle of one executor as a state machine over :class:`NodeExecutionStatus`.

    ``info`` is the node's :class:`NodeExecutionInfo`, or a callable returning it (a control node's flags
    change with its running children). The executor calls the transitions; the TST execution system calls
    ``abort`` and the ``*_requested`` methods. ``status`` is an immutable snapshot, replaced on each
    accepted transition and untouched by a refused one.
    """

    def __init__(self, info: NodeExecutionInfo | Callable[[], NodeExecutionInfo], name: str = "") -> None:
        self._info = info
        self.name = name
        self.status = NodeExecutionStatus()

    @property
    def info(self) -> NodeExecutionInfo:
        return self._info() if callable(self._info) else self._info

    # --- the executor's own transitions ----------------------------------------------------------------
    def prepare(self, ready: bool = True, reason: str = "") -> NodeExecutionStatus:
        """Fig. 3 prepare(): active if the platform is ready, else finished with ``reason``."""
        s = self.status
        if s.active or s.finished:
            raise self._refuse("prepare", "already prepared" if not s.finished else "already finished")
        if ready:
            return self._set(replace(s, active=True), "prepare")
        return self._set(replace(s, finished=True, fail_reason=reason or "not ready"), "prepare (not ready)")

    def start(self, wait_conditions_met: bool = True) -> NodeExecutionStatus:
        """Fig. 3 start(): executing, or waiting while wait conditions are unmet."""
        s = self.status
        if not s.active or s.finished:
            raise self._refuse("start", "not prepared" if not s.finished else "already finished")
        if s.waiting or s.executing:
            raise self._refuse("start", "already started")
        return self._set(replace(s, waiting=not wait_conditions_met, executing=wait_conditions_met), "start")

    def conditions_met(self) -> NodeExecutionStatus:
        """All wait conditions are met: waiting -> executing."""
        if not self.status.waiting:
            raise self._refuse("conditions_met", "not waiting")
        return self._set(replace(self.status, waiting=False, executing=True), "conditions met")

    def succeed(self) -> NodeExecutionStatus:
        """The task ran its course ("arrives at the desired location or completes a landing")."""
        s = self.status
        if not s.executing:
            raise self._refuse("succeed", "not executing")
        if s.paused:
            raise self._refuse("succeed", "paused")
        return self._set(replace(s, executing=False, finished=True, succeeded=True), "succeeded")

    def fail(self, reason: str) -> NodeExecutionStatus:
        """The task failed (prepared, waiting or executing) with ``reason`` for the operator."""
        s = self.status
        if not s.active or s.finished:
            raise self._refuse("fail", "not prepared" if not s.finished else "already finished")
        return self._set(_finish(s, fail_reason=reason or "failed"), f"failed: {reason}")

    # --- the execution system's requests ---------------------------------------------------------------
    def abort(self, reason: str = "") -> NodeExecutionStatus:
        """Abort ("an abnormal and urgent stopping"); refused while executing unless can_be_aborted."""
        s = self.status
        if not s.active or s.finished:
            raise self._refuse("abort", "not prepared" if not s.finished else "already finished")
        if s.executing and not self.info.can_be_aborted:
            raise self._refuse("abort", "can_be_aborted is false")
        text = f"aborted: {reason}" if reason else "aborted"
        return self._set(_finish(s, aborted=True, fail_reason=text), text)

    def pause_requested(self) -> NodeExecutionStatus:
        s = self.status
        if not s.executing:
            raise self._refuse("pause", "not executing" if not s.finished else "already finished")
        if not self.info.can_be_paused:
            raise self._refuse("pause", "can_be_paused is false")
        if s.paused:
            raise self._refuse("pause", "already paused")
        return self._set(replace(s, paused=True), "paused")

    def continue_requested(self) -> NodeExecutionStatus:
        if not self.status.paused:
            raise self._refuse("continue", "not paused")
        return self._set(replace(self.status, paused=False), "continued")

    def enough_requested(self) -> NodeExecutionStatus:
        s = self.status
        if not s.executing:
            raise self._refuse("enough", "not executing" if not s.finished else "already finished")
        if not self.info.can_be_enoughed:
            raise self._refuse("enough", "can_be_enoughed is false")
        return self._set(_finish(s, succeeded=True), "enoughed")

    # --- helpers ----------------------------------------------------------------------------------------
    def _refuse(self, what: str, why: str) -> ExecutionRequestError:
        who = f"{self.name}: " if self.name else ""
        return ExecutionRequestError(f"{who}{what} refused: {why}")

    def _set(self, status: NodeExecutionStatus, what: str) -> NodeExecutionStatus:
        bad = status.violations()
        if bad:  # a programming error in this class, never a user's request
            raise AssertionError(f"inconsistent status after {what}: {', '.join(bad)}")
        self.status = status
        log.debug("%s%s -> %s", f"{self.name}: " if self.name else "", what, status.state)
        return status


def _finish(s: NodeExecutionStatus, **changes: Any) -> NodeExecutionStatus:
    return replace(s, waiting=False, executing=False, paused=False, finished=True, **changes)
