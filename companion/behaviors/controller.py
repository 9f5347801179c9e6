"""Behavior execution controllers (seed 001 Sec. 6.1.1, 6.2.1) and the causes of termination (Sec. 5.2.1).

Each behavior has one execution controller offering the paper's three services:

1. *checking activation conditions* (:meth:`BehaviorExecutionController.check_activation`): the
   situation conditions, read from the belief memory (LAND needs ``flight_state(self, flying)``);
2. *starting the behavior* (:meth:`start`): ask the process manager for the catalog's processes,
   then give them their input (a flight behavior puts its flight commands on the queue);
3. *stopping the behavior* (:meth:`stop`): tell the process manager the processes are unused.

and monitors the performance conditions (:meth:`monitor`, called periodically on the autopilot's
clock), ending the behavior with a :class:`Termination`: ``goal_achieved``, ``time_out`` (the limit
:func:`~.timeouts.time_limit` derives from the plan and the catalog's ``timeout``, counted while the
behavior is not paused; goal-based behaviors only), ``wrong_progress`` (e.g. no progress toward the
goal for the catalog's ``performance.no_progress_s``) or ``interrupted`` (someone else cancelled its
commands or took the vehicle).

:class:`FlightBehavior` is the common base of the flight maneuvers: it puts its commands on the queue
with one atomic verb (:meth:`~companion.flight.queue.CommandQueue.replace_commands`, so switching
behaviors keeps the setpoint stream continuous) and follows them through the queue's events. Its goal
is the *vehicle*, not the setpoint (Sec. 6.2.1: the controller watches the robot): once every command
ended, ``goal_achieved`` only when the measured state (``ctx.vehicle()``, from the autopilot) is within
the catalog's ``goal`` tolerances; still short of it after ``goal.settle_s`` (held by the autopilot's
fence, by wind): ``wrong_progress``.

A new behavior is one module in :mod:`companion.behaviors.library` with a controller class
registered by :func:`register`, plus a descriptor in the catalog.
"""

from __future__ import annotations

import logging
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, Any, ClassVar

from companion.flight import EventKind, FlightCommand
from companion.flight.qapi import QueueError
from companion.flight.setpoint import VehicleState

from .catalog import BehaviorDescriptor
from .processes import ProcessError, ProcessManager
from .timeouts import time_limit

if TYPE_CHECKING:
    from companion.flight.queue import CommandQueue

    from .beliefs import BeliefMemory

log = logging.getLogger(__name__)

#: the goal's tolerances when the catalog gives none (``goal: {tolerance_m, tolerance_deg, settle_s}``)
DEFAULT_TOLERANCE_M = 1.0
DEFAULT_TOLERANCE_DEG = 10.0
DEFAULT_SETTLE_S = 10.0


class TerminationCause(Enum):
    """Sec. 5.2.1."""

    GOAL_ACHIEVED = "goal_achieved"
    TIME_OUT = "time_out"
    WRONG_PROGRESS = "wrong_progress"
    INTERRUPTED = "interrupted"


@dataclass(frozen=True)
class Termination:
    cause: TerminationCause
    detail: str = ""


class UnreachableError(ValueError):
    """A flight behavior's goal cannot be reached (raised by ``commands()``; ends it with wrong_progress)."""


class StartError(RuntimeError):
    """A behavior could not start (its processes or the queue refused); the activation is rejected."""


@dataclass
class BehaviorContext:
    """What execution controllers may use: the queue, the beliefs, the processes, the clock, the vehicle."""

    queue: CommandQueue
    beliefs: BeliefMemory
    processes: ProcessManager
    now: Callable[[], float]
    vehicle: Callable[[], VehicleState | None]
    extras: dict[str, Any] = field(default_factory=dict)


_REGISTRY: dict[str, type[BehaviorExecutionController]] = {}


def register(cls: type[BehaviorExecutionController]) -> type[BehaviorExecutionController]:
    """Class decorator: the execution controller of ``cls.behavior``."""
    if not cls.behavior:
        raise ValueError(f"{cls.__name__} names no behavior")
    _REGISTRY[cls.behavior] = cls
    return cls


def controller_class(behavior: str) -> type[BehaviorExecutionController] | None:
    from . import library  # noqa: F401  (importing the package registers the bundled behaviors)

    return _REGISTRY.get(behavior)


class BehaviorExecutionController:
    """Base class (see module docstring). Subclasses set ``behavior`` and override the ``on_*`` hooks."""

    behavior: ClassVar[str] = ""

    def __init__(self, descriptor: BehaviorDescriptor, ctx: BehaviorContext) -> None:
        self.descriptor = descriptor
        self.ctx = ctx
        self.params: Mapping[str, Any] = {}
        self.activation_id: str | None = None
        self.active = False
        self.started_at: float | None = None
        self._paused_since: float | None = None
        self._paused_total = 0.0
        self.time_limit_s: float | None = None

    # --- the three services (Sec. 6.2.1) -------------------------------------------------------------------
    def check_activation(self, params: Mapping[str, Any]) -> str | None:
        """The situation conditions: None when they hold, else why not."""
        return self.situation(params)

    def start(self, params: Mapping[str, Any], activation_id: str) -> None:
        """Launch the processes, then give them their input; :class:`StartError` when impossible."""
        self.params = dict(params)
        self.activation_id = activation_id
        self.started_at = self.ctx.now()
        self._paused_since = None
        self._paused_total = 0.0
        self.time_limit_s = self.plan_time_limit(self.params)
        try:
            self.ctx.processes.request_start(self.descriptor.processes, self.behavior)
        except ProcessError as exc:
            raise StartError(str(exc)) from None
        try:
            self.on_start(self.params)
        except (StartError, QueueError, ValueError) as exc:
            self.ctx.processes.release(self.descriptor.processes, self.behavior)
            raise StartError(str(exc)) from None
        self.active = True

    def stop(self) -> None:
        """Stop the behavior: its own clean-up, then its processes are released (stopped later if unused)."""
        if not self.active:
            return
        self.active = False
        try:
            self.on_stop()
        finally:
            self.ctx.processes.release(self.descriptor.processes, self.behavior)

    # --- performance monitoring --------------------------------------------------------------------------
    def monitor(self, now_s: float) -> Termination | None:
        """Check the performance conditions; a :class:`Termination` ends the behavior."""
        if not self.active:
            return None
        ended = self.performance(now_s)
        if ended is not None:
            return ended
        timeout = self.time_limit_s
        if timeout and self.active_time(now_s) > timeout:
            return Termination(TerminationCause.TIME_OUT, f"not achieved within {timeout:.0f} s (the limit "
                                                          "of its plan)" if self.descriptor.timeout_plan
                               else f"not achieved within {timeout:g} s")
        return None

    def plan_time_limit(self, params: Mapping[str, Any]) -> float | None:
        """The time-out of this activation (:func:`~.timeouts.time_limit` from where the vehicle is now)."""
        limits = getattr(self.ctx.queue, "limits", None)
        if limits is None:
            return self.descriptor.timeout_s if self.descriptor.category == "goal_based" else None
        start, heading = self.start_point()
        return time_limit(self.descriptor, params, limits, start, heading)

    def start_point(self) -> tuple[tuple[float, float, float], float | None]:
        """Where the vehicle is ((north, east, up): measured, else the reference, else home) and its
        heading in degrees (None when unknown)."""
        v = self.ctx.vehicle()
        if v is not None:
            return (float(v.p[0]), float(v.p[1]), -float(v.p[2])), math.degrees(v.yaw) % 360.0
        ref = getattr(self.ctx.queue, "reference", None)
        if ref is not None:
            return (float(ref.p[0]), float(ref.p[1]), float(ref.altitude)), None
        return (0.0, 0.0, 0.0), None

    def active_time(self, now_s: float) -> float:
        """Seconds active, not counting paused spans (an operator's break-in does not time a behavior out)."""
        if self.started_at is None:
            return 0.0
        paused = self._paused_total + (now_s - self._paused_since if self._paused_since is not None else 0.0)
        return max(0.0, now_s - self.started_at - paused)

    def set_paused(self, paused: bool, now_s: float) -> None:
        if paused and self._paused_since is None:
            self._paused_since = now_s
        elif not paused and self._paused_since is not None:
            self._paused_total += now_s - self._paused_since
            self._paused_since = None

    @property
    def paused(self) -> bool:
        return self._paused_since is not None

    # --- hooks --------------------------------------------------------------------------------------------
    def situation(self, params: Mapping[str, Any]) -> str | None:
        return None

    def on_start(self, params: Mapping[str, Any]) -> None:
        pass

    def on_stop(self) -> None:
        pass

    def performance(self, now_s: float) -> Termination | None:
        return None

    def status(self) -> dict[str, Any]:
        return {"time_limit_s": round(self.time_limit_s, 1) if self.time_limit_s else None}

    # --- helpers for situation conditions -------------------------------------------------------------------
    def need(self, query: str, why: str) -> str | None:
        """None when the belief query holds, else ``why``."""
        return None if self.ctx.beliefs.holds(query) else why

    def flight_state(self) -> str | None:
        value = self.ctx.beliefs.value("flight_state", "self")
        return str(value) if value is not None else None


class FlightBehavior(BehaviorExecutionController, ABC):
    """A flight maneuver: its commands on the queue, followed through the queue's events.

    Subclasses give :meth:`commands`; ``goal_distance`` (optional) is the measured distance to the
    goal, used for the catalog's progress condition ``performance: {no_progress_s, progress_m}`` and,
    by default, for the goal itself (:meth:`goal_check`, within ``goal.tolerance_m``). A behavior whose
    goal is not a measured state (WAIT, KEEP_HOVERING ended by the operator) sets ``measured_goal``
    False.
    """

    measured_goal: ClassVar[bool] = True

    def __init__(self, descriptor: BehaviorDescriptor, ctx: BehaviorContext) -> None:
        super().__init__(descriptor, ctx)
        self.command_ids: list[int] = []
        self.finished: set[int] = set()
        self._seq = 0
        self._best: float | None = None
        self._best_at = 0.0
        self.unreachable: str | None = None
        self.commands_done_at: float | None = None
        self.short_of_goal: str | None = None

    @abstractmethod
    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        """The flight commands that perform the behavior (seed 000 Fig. 11-14)."""

    def goal_distance(self, vehicle: VehicleState) -> float | None:
        return None

    def goal_reached(self) -> bool:
        """Called once every command finished; True: goal_achieved (override to wait for more)."""
        return True

    def goal_check(self, vehicle: VehicleState | None) -> str | None:
        """None when the measured state meets the goal, else what is missing (Sec. 6.2.1: the controller
        watches the robot). By default :meth:`goal_distance` within the catalog's ``goal.tolerance_m``."""
        if not self.measured_goal:
            return None
        if vehicle is None:
            return "the autopilot reports no position"
        d = self.goal_distance(vehicle)
        if d is None:
            return None
        tol = self.descriptor.goal.get("tolerance_m", DEFAULT_TOLERANCE_M)
        return None if d <= tol else f"the vehicle is {d:.1f} m from the goal (tolerance {tol:g} m)"

    def on_start(self, params: Mapping[str, Any]) -> None:
        if self.ctx.queue.status().queue_system_status.name == "OVERRIDDEN":
            raise StartError("the vehicle is controlled elsewhere (the queue is OVERRIDDEN)")
        self.unreachable = None
        try:
            commands = self.commands(params)
        except UnreachableError as exc:  # stop what the previous behavior did, then end at the first check
            self.unreachable = str(exc)
            commands = [FlightCommand()]  # hold where the reference is (E_User)
        self._seq = self.ctx.queue.events.last_seq
        self.command_ids = self.ctx.queue.replace_commands(commands)
        self.finished = set()
        self._best = None
        self._best_at = self.started_at or 0.0
        self.commands_done_at = None
        self.short_of_goal = None

    def performance(self, now_s: float) -> Termination | None:
        if self.unreachable is not None:
            return Termination(TerminationCause.WRONG_PROGRESS, f"unreachable: {self.unreachable}")
        ids = set(self.command_ids)
        for ev in self.ctx.queue.events.since(self._seq):
            self._seq = ev.seq
            if ev.kind is EventKind.OVERRIDDEN:
                return Termination(TerminationCause.INTERRUPTED, "the vehicle was taken over")
            if ev.command_id not in ids:
                continue
            if ev.kind is EventKind.FINISHED:
                self.finished.add(ev.command_id)
                self._best, self._best_at = None, now_s  # a new leg: progress counts afresh
            elif ev.kind is EventKind.FAILED:
                return Termination(TerminationCause.WRONG_PROGRESS, f"command failed: {ev.detail}")
            elif ev.kind is EventKind.CANCELLED:
                return Termination(TerminationCause.INTERRUPTED, "its commands were cancelled")
            elif ev.kind is EventKind.PAUSED:
                self.set_paused(True, now_s)
            elif ev.kind in (EventKind.RESUMED, EventKind.STOPPED):
                self.set_paused(ev.kind is EventKind.STOPPED, now_s)
        if len(self.finished) == len(ids):
            ended = self._judge_goal(now_s)
            if ended is not None:
                return ended
        return self._progress(now_s)

    def _judge_goal(self, now_s: float) -> Termination | None:
        """Every command ended: goal_achieved once the vehicle meets the goal; wrong_progress when it is
        still short of it ``goal.settle_s`` later."""
        if self.commands_done_at is None:
            self.commands_done_at = now_s
        why = None if self.goal_reached() else "the goal is not reached yet"
        why = why or self.goal_check(self.ctx.vehicle())
        self.short_of_goal = why
        if why is None:
            return Termination(TerminationCause.GOAL_ACHIEVED)
        settle = self.descriptor.goal.get("settle_s", DEFAULT_SETTLE_S)
        if now_s - self.commands_done_at > settle:
            return Termination(TerminationCause.WRONG_PROGRESS,
                               f"its commands ended but {why} {settle:g} s later")
        return None

    def _progress(self, now_s: float) -> Termination | None:
        window = self.descriptor.performance.get("no_progress_s")
        vehicle = self.ctx.vehicle()
        if not window or vehicle is None or self.paused:
            if self.paused:
                self._best_at = now_s
            return None
        d = self.goal_distance(vehicle)
        if d is None:
            return None
        step = self.descriptor.performance.get("progress_m", 0.5)
        if self._best is None or d < self._best - step:
            self._best, self._best_at = d, now_s
            return None
        if d <= step:  # at the goal: waiting for the reference to settle is not a lack of progress
            self._best_at = now_s
            return None
        if now_s - self._best_at > window:
            return Termination(TerminationCause.WRONG_PROGRESS,
                               f"no progress toward the goal for {window:g} s ({d:.1f} m away)")
        return None

    def status(self) -> dict[str, Any]:
        out = {**super().status(), "command_ids": list(self.command_ids), "finished": len(self.finished)}
        if self.short_of_goal is not None:
            out["short_of_goal"] = self.short_of_goal
        return out


def distance(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    return math.dist(a, b)


def ned_of(point_neu: tuple[float, float, float]) -> tuple[float, float, float]:
    """(north, east, up) as an operator writes it -> local NED."""
    return (float(point_neu[0]), float(point_neu[1]), -float(point_neu[2]))
