"""The Switchboard (seed 003 Sec. III-B): which controller flies the vehicle, one at a time.

Seed 003: "A supervisor process referred to as Switchboard recognizes which controller process
corresponds to the current task. The command output from that process is directed to the Piccolo
process and thereby forwarded to the avionics ... It also abides by the policy that each variable has
only one process with write permission."

Here the controllers are the mission layer's Task Specification Trees: the TST of the team task the
vehicle holds (:mod:`companion.team.task_tst`), a mission or task given directly by the process monitor
(the directed tier), and loitering (no TST: the executive layer's default behavior holds the vehicle where
it is, seed 001). :class:`Switchboard` is the only part of the team layer that starts or aborts a TST, so
at any time exactly one of them is the requester of the vehicle's flight behaviors, and the behavior
coordinator is the one writer of the flight-command queue. A hand-over is an abort of the running tree
(its behavior is inhibited: the default hover takes over from the current reference) followed by the
start of the next (its first behavior replaces the hover through the queue's ``replace_commands`` verb),
so the setpoint stream stays continuous: the queue's reference never jumps.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING

from companion.tst.status import ExecutionRequestError

from .task_tst import mission_for
from .types import TeamTask

if TYPE_CHECKING:
    from companion.mission_service import MissionService

log = logging.getLogger(__name__)


class Controller(StrEnum):
    """Who writes the vehicle's flight behaviors now."""

    LOITER = "loiter"        #: no tree: the default behavior holds the vehicle where it is
    TEAM = "team"            #: the TST of the held team task
    DIRECTED = "directed"    #: a mission or task given by the process monitor (the team keeps out)
    NONE = "none"            #: a ground station took the autopilot (mode change): nothing is written


@dataclass(frozen=True)
class Outcome:
    """How the tree of the current task is doing: running, succeeded or failed (with the reason)."""

    task: int
    state: str
    reason: str = ""


class Switchboard:
    """See module docstring. Thread-safe; every method returns quickly (no waiting on the vehicle)."""

    def __init__(self, missions: MissionService, standard_altitude: float = 10.0) -> None:
        self.missions = missions
        self.standard_altitude = standard_altitude
        self.controller = Controller.LOITER
        self.task: TeamTask | None = None
        self.handovers = 0
        self.errors: list[str] = []
        self._lock = threading.RLock()

    # --- hand-overs -------------------------------------------------------------------------------------
    def fly(self, task: TeamTask, on_ground: bool, controller: Controller = Controller.TEAM) -> bool:
        """Make the TST of ``task`` the writer. False (and the vehicle loiters) if its delegation failed."""
        with self._lock:
            if self.controller is controller and self.task is not None and self.task.id == task.id \
                    and self.task.version == task.version:
                return True
            self._stop_tree()
            mission = mission_for(task, on_ground, self.standard_altitude)
            try:
                result = self.missions.submit(mission)
            except ExecutionRequestError as exc:
                self._failed(task, str(exc))
                return False
            if not result.accepted:
                self._failed(task, "; ".join(result.reasons))
                return False
            try:
                self.missions.start()
            except ExecutionRequestError as exc:
                self._failed(task, str(exc))
                return False
            self.controller, self.task = controller, task
            self.handovers += 1
            log.info("switchboard: %s task %d v%d (%s)", controller.value, task.id, task.version,
                     task.kind.value)
            return True

    def loiter(self) -> None:
        """No task: abort the tree (if any); the vehicle holds where it is (seed 003: "loiter")."""
        with self._lock:
            if self.controller is Controller.LOITER and self.task is None:
                return
            self._stop_tree()
            self.controller, self.task = Controller.LOITER, None
            log.info("switchboard: loiter")

    def hand_to(self, controller: Controller) -> None:
        """Give the vehicle to a lower tier: the team's tree (if any) is aborted and nothing of the team
        is written until :meth:`loiter` or :meth:`fly` takes it back."""
        with self._lock:
            if self.controller is Controller.TEAM:
                self._stop_tree()
            if self.controller is not controller:
                log.info("switchboard: %s", controller.value)
            self.controller, self.task = controller, None

    # --- what the tree does ------------------------------------------------------------------------------
    def outcome(self) -> Outcome | None:
        """The state of the current task's tree (None without a task)."""
        with self._lock:
            if self.task is None:
                return None
            status = self.missions.execution.root_status()
            if status is None:
                return Outcome(self.task.id, "loaded")
            return Outcome(self.task.id, status.state, status.fail_reason)

    def _stop_tree(self) -> None:
        if self.missions.execution.running:
            try:
                self.missions.abort("switchboard: hand-over", policy="hover")
            except ExecutionRequestError as exc:  # finished meanwhile
                log.debug("%s", exc)

    def _failed(self, task: TeamTask, reason: str) -> None:
        text = f"task {task.id}: {reason}"
        log.warning("switchboard: %s", text)
        self.errors.append(text)
        del self.errors[:-20]
        self.controller, self.task = Controller.LOITER, None
