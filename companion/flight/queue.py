"""The flight command queue with the QAPI verbs and status (seed 000 Sec. IV-B and Sec. V).

:class:`CommandQueue` holds the list of flight commands and executes them in sequence; its owner (the
MAVLink link) calls :meth:`CommandQueue.tick` at the streaming rate with the time and the measured
vehicle state and streams the returned :class:`~companion.flight.setpoint.Setpoint`. Other threads
(the HTTP control surface, pause_routines) call the verbs. One lock guards all state; only the queue's
own methods change it (one writer). Every change of a command's life is published as a
:class:`~companion.flight.events.QueueEvent` on :attr:`CommandQueue.events` (wait on it or subscribe).

The verbs (Sec. V), the decisions where the paper is silent, the status fields and the link's tick
contract are documented in :mod:`companion.flight.qapi`.

"Stopped if allowed" during a take-off (Sec. V): see :mod:`.takeoff_rule` (the queue owns a
:class:`~.takeoff_rule.TakeoffStopRule` and carries out the verbs it deferred).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace

from taskflight_common.clock import Clock

from .commands import CommandError, FlightCommand
from .events import EventKind, EventLog, QueueEvent, new_command_id
from .execution import CommandExecution, streamed_setpoint
from .external import DEFAULT_MAX_VALIDITY_S, DEFAULT_SOURCE, ExternalData, ExternalDataError, Sample
from .limits import Envelope, Limits
from .pause_routines import DEFAULT_ROUTINE, PauseRoutine, PauseRoutineCatalog, default_catalog
from .qapi import (
    CommandStatus,
    QueuedCommand,
    QueueError,
    QueueState,
    QueueStateError,
    QueueStatus,
    QueueSystemStatus,
)
from .reference import HOLD, Reference, ReferenceGenerator
from .retarget import Retarget, RetargetError, retargeted
from .setpoint import Setpoint, VehicleState
from .takeoff_rule import TAKEOFF_MIN_HOLD_M, TakeoffStopRule

log = logging.getLogger(__name__)


@dataclass
class _ActiveRoutine:
    routine: PauseRoutine
    index: int
    execution: CommandExecution | None
    continuing: bool  # what the queue does afterwards: continue (True) or stay stopped


class CommandQueue:
    """The QAPI command queue (see module docstring)."""

    def __init__(self, limits: Limits | None = None, envelope: Envelope | None = None,
                 catalog: PauseRoutineCatalog | None = None, clock: Clock | None = None,
                 max_step_s: float = 1.0, max_validity_s: float = DEFAULT_MAX_VALIDITY_S,
                 takeoff_min_hold_m: float = TAKEOFF_MIN_HOLD_M) -> None:
        self.limits = limits or Limits()
        self.envelope = envelope or Envelope()
        self.catalog = catalog or default_catalog()
        self.events = EventLog()
        self._clock = clock
        self._max_step_s = max_step_s
        self._lock = threading.RLock()
        self._depth = 0
        self._outbox: list[QueueEvent] = []
        self._gen = ReferenceGenerator(self.limits, self.envelope)
        self._ext = ExternalData(max_validity_s)
        self._commands: list[QueuedCommand] = []
        self._generation = 0
        self._index = 0
        self._exec: CommandExecution | None = None
        self._state = QueueState.STOPPED
        self._routine: _ActiveRoutine | None = None
        self._pending_pause: PauseRoutine | None = None
        self._takeoff = TakeoffStopRule(takeoff_min_hold_m)
        self._failure: str | None = None
        self._overridden = False
        self._synced = False
        self._ref: Reference | None = None
        self._last_t: float | None = None
        self._last_setpoint: Setpoint | None = None
        self._limit_reached = False
        self._unreachable = False
        self._velocity_only = False  # the last tick streamed velocity only

    # --- locking and events ----------------------------------------------------------------------------
    @contextmanager
    def _locked(self) -> Iterator[None]:
        """The queue's lock; events recorded inside are dispatched to subscribers after it is released."""
        events: list[QueueEvent] = []
        with self._lock:
            self._depth += 1
            try:
                yield
            finally:
                self._depth -= 1
                if self._depth == 0 and self._outbox:
                    events, self._outbox = self._outbox, []
        if events:
            self.events.dispatch(events)

    def _emit(self, kind: EventKind, entry: QueuedCommand | None = None, index: int | None = None,
              detail: str = "") -> None:
        event = self.events.record(kind, entry.id if entry else None, index, self._generation, self._last_t,
                                   detail)
        self._outbox.append(event)

    def _current_entry(self) -> QueuedCommand | None:
        return self._commands[self._index] if self._index < len(self._commands) else None

    # --- QAPI verbs ----------------------------------------------------------------------------------
    def check_command(self, command: FlightCommand) -> None:
        """Raise what :meth:`add_command` would (QueueError, CommandError); change nothing."""
        if not isinstance(command, FlightCommand):
            raise QueueError(f"expected a FlightCommand, got {type(command).__name__}")
        self.envelope.check_command(command)

    def add_command(self, command: FlightCommand) -> int:
        """Append a command; returns its id (unique for the life of the process)."""
        return self.add_commands([command])[0]

    def add_commands(self, commands: Sequence[FlightCommand]) -> list[int]:
        """Append ``commands`` at once after checking them all (all or none); returns their ids."""
        commands = list(commands)
        if not commands:
            return []
        self._check_all(commands)
        with self._locked():
            ids = [self._append(c) for c in commands]
            log.info("commands %s added", ids)
            self._maybe_start()
            return ids

    def replace_commands(self, commands: Sequence[FlightCommand]) -> list[int]:
        """``reset()``, ``add_commands(commands)`` and ``run()`` as one verb, with no tick in between:
        how the behaviors (seed 001) switch flight maneuvers while the setpoint stream stays
        continuous (the new commands start from the reference as it is, moving or not). Checked
        first (all or none). During a take-off that may not be stopped yet it is deferred like
        ``reset`` (the ids are returned at once; their ADDED events come when it is carried out)."""
        commands = list(commands)
        if not commands:
            raise QueueError("replace_commands: no commands")
        self._check_all(commands)
        with self._locked():
            self._refuse_if_overridden("replace_commands")
            entries = [QueuedCommand(new_command_id(), c) for c in commands]
            if not self._defer_if_taking_off("replace", None, entries):
                self._do_replace(entries)
            return [e.id for e in entries]

    def _check_all(self, commands: Sequence[FlightCommand]) -> None:
        for i, c in enumerate(commands):
            try:
                self.check_command(c)
            except CommandError as exc:
                if len(commands) == 1:
                    raise
                raise CommandError(f"commands[{i}].{exc.field}", exc.reason) from None
            except QueueError as exc:
                if len(commands) == 1:
                    raise
                raise QueueError(f"commands[{i}]: {exc}") from None

    def _append(self, command: FlightCommand, entry: QueuedCommand | None = None) -> int:
        entry = entry or QueuedCommand(new_command_id(), command)
        self._commands.append(entry)
        self._emit(EventKind.ADDED, entry, len(self._commands) - 1)
        return entry.id

    def _do_replace(self, entries: list[QueuedCommand]) -> None:
        self._do_reset()
        for e in entries:
            self._append(e.command, e)
        self._state = QueueState.RUNNING
        log.info("commands replaced by %s", [e.id for e in entries])
        self._maybe_start()

    def run(self) -> None:
        with self._locked():
            self._refuse_if_overridden("run")
            was_running = self._state is QueueState.RUNNING and self._routine is None
            cancelled = self._takeoff.cancel_pause()
            if cancelled is not None:
                log.info("run(): deferred %s cancelled", cancelled)
            if self._routine is not None:
                log.info("run(): abandoning pause routine %s", self._routine.routine.id)
                self._routine = None
                was_running = False
            self._state = QueueState.RUNNING
            self._failure = None
            if not was_running and self._exec is not None and self._ref is not None:
                self._exec.resume(self._ref)
                self._emit(EventKind.RESUMED, self._current_entry(), self._index)
            self._maybe_start()

    def stop(self) -> None:
        with self._locked():
            if self._defer_if_taking_off("stop", None):
                return
            self._do_stop()

    def pause_direct(self, routine_id: str | None = None) -> None:
        with self._locked():
            self._refuse_if_overridden("pause_direct")
            routine = self._routine_of(routine_id)
            if self._routine is not None:
                raise QueueStateError(f"pause_direct: already in pause routine "
                                      f"{self._routine.routine.id!r} (user_confirm or run() ends it)")
            if self._defer_if_taking_off("pause_direct", routine):
                return
            self._start_routine(routine, continuing=self._state is QueueState.RUNNING)

    def pause_after_current(self, routine_id: str | None = None) -> None:
        with self._locked():
            self._refuse_if_overridden("pause_after_current")
            routine = self._routine_of(routine_id)
            if self._routine is not None:
                raise QueueStateError(f"pause_after_current: already in pause routine "
                                      f"{self._routine.routine.id!r}")
            if self._pending_pause is not None:
                raise QueueStateError(f"pause_after_current: pause {self._pending_pause.id!r} "
                                      "already pending")
            if self._state is QueueState.RUNNING and self._index < len(self._commands):
                self._pending_pause = routine
                log.info("pause %s after command %d", routine.id, self._index)
            else:
                self._start_routine(routine, continuing=self._state is QueueState.RUNNING)

    def reset(self) -> None:
        with self._locked():
            if self._defer_if_taking_off("reset", None):
                return
            self._do_reset()

    def user_confirm(self) -> None:
        with self._locked():
            self._refuse_if_overridden("user_confirm")
            execution = self._active_execution()
            if execution is None or not execution.waiting_for_confirmation:
                what = "no command is executing" if execution is None else "the executing command does not " \
                    "wait for a user confirmation"
                raise QueueStateError(f"user_confirm: nothing is waiting for a confirmation ({what})")
            execution.confirm()
            if execution.ended:
                self._finish_active()

    def retarget(self, command_id: int, change: Retarget) -> FlightCommand:
        """Change the executing command's target in flight (Sec. IV-D); returns the command as it now reads.

        :class:`QueueStateError` if ``command_id`` is not the command executing (started and unfinished);
        :class:`QueueError` / :class:`CommandError` if the change does not fit it. Nothing changes then.
        """
        with self._locked():
            self._refuse_if_overridden("retarget")
            entry = self._current_entry()
            if entry is None or entry.id != command_id or self._exec is None or self._ref is None:
                raise QueueStateError(f"retarget: command {command_id} is not executing")
            try:
                new, changed = retargeted(entry.command, self._exec, change)
            except RetargetError as exc:
                raise QueueError(str(exc)) from None
            self.envelope.check_command(new)
            self._exec.retarget(new, self._ref, changed)
            entry.command = new
            self._emit(EventKind.RETARGETED, entry, self._index, change.describe())
            log.info("command %d retargeted: %s", entry.id, change.describe())
            return new

    # --- link side ------------------------------------------------------------------------------------
    def set_overridden(self, overridden: bool) -> None:
        """Called by the link: someone else took the vehicle (mode change, disarm) or gave it back."""
        with self._locked():
            if overridden and not self._overridden:
                log.warning("queue overridden: stopping, no more setpoints")
                self._state = QueueState.STOPPED
                self._routine = None
                self._pending_pause = None
                self._drop_deferred("the vehicle was taken over")
                self._ref = None
                self._last_setpoint = None
                self._emit(EventKind.OVERRIDDEN, self._current_entry(), self._index)
            self._overridden = bool(overridden)

    def set_synced(self, synced: bool) -> None:
        """Called by the link: the autopilot's POSITION_TARGET_LOCAL_NED echoes what we stream."""
        with self._lock:
            self._synced = bool(synced)

    def fail_current(self, reason: str) -> None:
        """Called by the link: it gave up the executing command (a take-off the autopilot refused).

        The queue stops; the command stays current with status FAILED and ``failure`` = ``reason``;
        ``run()`` tries it again.
        """
        with self._locked():
            entry = self._current_entry()
            self._failure = reason
            self._state = QueueState.STOPPED
            self._routine = None
            self._pending_pause = None
            self._drop_deferred(f"the take-off failed: {reason}")
            self._exec = None  # tried again, it starts afresh from wherever the vehicle is then
            self._emit(EventKind.FAILED, entry, self._index, reason)
            log.error("command %s failed: %s", entry.id if entry else None, reason)

    def push_external(self, stream: str, values: Sequence[float], validity_s: float,
                      t_s: float | None = None, source: str = DEFAULT_SOURCE) -> bool:
        """Store an external-data sample (Sec. IV-C); stamped with the clock (or the last tick) if no ``t_s``.
        False (ignored) when older than the stream's newest or not from the source it is tied to.

        Raises :class:`~companion.flight.external.ExternalDataError` when malformed (nothing changes).
        """
        with self._lock:
            if t_s is None:
                t_s = self._clock.now() if self._clock is not None else (self._last_t or 0.0)
            return self._ext.push(stream, values, validity_s, t_s, source)

    def select_external_source(self, stream: str, source: str | None) -> None:
        """Take ``stream``'s samples from ``source`` only (None: any), :meth:`ExternalData.select`."""
        with self._lock:
            self._ext.select(stream, source)

    def offer_external(self, stream: str, values: Sequence[float], validity_s: float, *, age_s: float = 0.0,
                       seq: int | None = None, sender: str | None = None) -> str | None:
        """A sample stamped where it was made, ``age_s`` before now: stored (None), or why it was dropped
        (stale on arrival, out of order; :meth:`ExternalData.offer`). Malformed: ExternalDataError."""
        if isinstance(age_s, bool) or not isinstance(age_s, int | float) or not math.isfinite(age_s) \
                or age_s < 0:
            raise ExternalDataError(f"{stream}: age must be a finite number of seconds >= 0, got {age_s!r}")
        with self._lock:
            now = self._clock.now() if self._clock is not None else (self._last_t or 0.0)
            return self._ext.offer(stream, values, validity_s, now - age_s, seq=seq, sender=sender, now_s=now)

    def external_sample(self, stream: str) -> Sample | None:
        """The newest sample of an external stream, fresh or not (read-only view)."""
        with self._lock:
            return self._ext.sample(stream)

    def executing_take_off(self) -> bool:
        """True while the command executing now is a take-off (the link keeps its take-off going)."""
        with self._lock:
            ex = self._active_execution()
            return ex is not None and ex.command.vertical.take_off and not ex.ended

    def mark_takeoff_airborne(self, vehicle: VehicleState | None = None) -> bool:
        """Called by the link when the vehicle lifted off for the executing take-off; False when the
        take-off is no longer executing (stopped, reset or paused meanwhile). Atomic with the verbs: a
        stop after it is deferred, a stop before it makes it answer False.

        With ``vehicle``, the reference restarts at the measured state (the autopilot's own take-off
        has already climbed by the time the lift-off is seen): the first streamed setpoint continues
        the climb where the vehicle is, instead of pulling it back to the ground it left."""
        with self._lock:
            ex = self._active_execution()
            if ex is None or self._routine is not None or not ex.command.vertical.take_off or ex.ended:
                return False
            ex.airborne = True
            if vehicle is not None and self._ref is not None:
                self._ref = self._gen.initial(self._ref.t_s, vehicle.p, vehicle.v, vehicle.yaw)
                ex.resume(self._ref)
                self._last_setpoint = None
            return True

    @property
    def takeoff_min_hold_m(self) -> float:
        """A climbing take-off may not be stopped below this height above where it started (m)."""
        return self._takeoff.min_hold_m

    @property
    def max_validity_s(self) -> float:
        return self._ext.max_validity_s

    # --- status ------------------------------------------------------------------------------------------
    def status(self) -> QueueStatus:
        with self._lock:
            execution = self._active_execution()
            entry = self._current_entry()
            return QueueStatus(
                queue_system_status=(QueueSystemStatus.OVERRIDDEN if self._overridden
                                     else QueueSystemStatus.RUNNING),
                queue_status=self._queue_state(),
                current_command_index=self._index,
                current_command_status=self._command_status(),
                confirmation_required_status=execution is not None and execution.waiting_for_confirmation,
                limit_reached=self._limit_reached,
                target_position_unreachable=self._unreachable,
                is_synced=self._synced,
                current_command_id=entry.id if entry else None,
                generation=self._generation,
                failure=self._failure,
                deferred=self._takeoff.deferred.verb if self._takeoff.deferred else None)

    @property
    def commands(self) -> tuple[FlightCommand, ...]:
        with self._lock:
            return tuple(e.command for e in self._commands)

    @property
    def entries(self) -> tuple[QueuedCommand, ...]:
        """(id, command) of each command in the list (copies)."""
        with self._lock:
            return tuple(QueuedCommand(e.id, e.command) for e in self._commands)

    @property
    def routine_id(self) -> str | None:
        """The pause routine running, if any."""
        with self._lock:
            return self._routine.routine.id if self._routine else None

    @property
    def reference(self) -> Reference | None:
        with self._lock:
            return self._ref

    @property
    def guard_interventions(self) -> int:
        return self._gen.guard_interventions

    # --- the tick ----------------------------------------------------------------------------------------
    def tick(self, now_s: float, vehicle_state: VehicleState | None = None, *,
             follow_vehicle: bool = False) -> Setpoint | None:
        """Advance to ``now_s`` and return the setpoint to stream (:mod:`.qapi`, tick contract)."""
        with self._locked():
            if self._overridden:
                return None
            follow = follow_vehicle and vehicle_state is not None and self._active_execution() is None
            if self._ref is None or follow:
                if vehicle_state is None:
                    raise ValueError("tick: the first tick (and the first after an override) needs "
                                     "the vehicle state")
                self._ref = self._gen.initial(now_s, vehicle_state.p, vehicle_state.v, vehicle_state.yaw)
                self._last_t = now_s
                self._maybe_start()
                self._last_setpoint = self._setpoint(self._active_execution(), False)
                return self._last_setpoint
            assert self._last_t is not None
            elapsed = now_s - self._last_t
            if elapsed <= 0 and self._last_setpoint is not None:
                return self._last_setpoint
            self._last_t = now_s
            dt = min(elapsed, self._max_step_s)
            self._maybe_start()
            execution = self._active_execution()
            self._after_velocity_only(execution, vehicle_state)
            land_now = False
            if execution is None:
                result = self._gen.step(self._ref, HOLD, dt)
            else:
                outcome = execution.step(self._ref, dt, elapsed, now_s, self._ext, self._gen, vehicle_state)
                result = outcome.step
                land_now = outcome.land_now
                if execution.failure is not None:  # V_GROUND lost its range finder: altitude held
                    self._ref = replace(result.reference, t_s=now_s)
                    self.fail_current(execution.failure)
                    self._last_setpoint = self._setpoint(None, False)
                    return self._last_setpoint
            self._ref = replace(result.reference, t_s=now_s)
            self._limit_reached = result.limit_reached
            self._unreachable = result.target_unreachable
            setpoint = self._setpoint(execution, land_now)
            if execution is not None and execution.ended:
                self._finish_active()
            self._apply_deferred()
            self._last_setpoint = setpoint
            return setpoint

    # --- internals (call with the lock held) ------------------------------------------------------------
    def _after_velocity_only(self, execution: CommandExecution | None, vehicle: VehicleState | None) -> None:
        """The first position tick after velocity-only ones starts at the measured position.

        Velocity-only setpoints give the autopilot no position (ExtVel, RCVel: it flies the velocity);
        the reference's integrated position drifts from where the vehicle is. Restarting the position
        there (velocity and acceleration kept: the stream stays continuous) spares the autopilot a step
        of its target when a position command follows (a break-in resumed, a joystick confirmed)."""
        velocity_only = execution is not None and execution.command.velocity_only
        if self._velocity_only and not velocity_only and vehicle is not None and self._ref is not None:
            north, east, down = vehicle.p
            self._ref = replace(self._ref, p=(float(north), float(east), float(down)))
            if execution is not None:
                execution.resume(self._ref)
        self._velocity_only = velocity_only

    def _refuse_if_overridden(self, verb: str) -> None:
        if self._overridden:
            raise QueueStateError(f"{verb}: the queue is OVERRIDDEN (the vehicle is controlled elsewhere)")

    def _routine_of(self, routine_id: str | None) -> PauseRoutine:
        bid = DEFAULT_ROUTINE if routine_id is None else routine_id
        try:
            return self.catalog.get(bid)
        except KeyError as exc:
            raise QueueError(str(exc.args[0])) from None

    def _takeoff_unstoppable(self) -> bool:
        own = self._exec if self._routine is None and self._state is QueueState.RUNNING else None
        return self._takeoff.unstoppable(own, self._ref)

    def _defer_if_taking_off(self, verb: str, routine: PauseRoutine | None,
                             entries: Sequence[QueuedCommand] = ()) -> bool:
        """Defer ``verb`` if the take-off may not stop yet (True then); :mod:`.takeoff_rule`."""
        if not self._takeoff_unstoppable():
            return False
        for e in self._takeoff.defer(verb, routine, entries):
            self._emit(EventKind.CANCELLED, e, None, f"superseded by a later {verb}")
        text = f"{verb} deferred until the take-off is {self.takeoff_min_hold_m:g} m up"
        log.info("%s", text)
        self._emit(EventKind.DEFERRED, self._current_entry(), self._index, text)
        return True

    def _drop_deferred(self, why: str) -> None:
        deferred = self._takeoff.take()
        for e in deferred.entries if deferred is not None else ():
            self._emit(EventKind.CANCELLED, e, None, why)

    def _apply_deferred(self) -> None:
        if self._takeoff.deferred is None or self._takeoff_unstoppable():
            return
        deferred = self._takeoff.take()
        assert deferred is not None
        log.info("carrying out the deferred %s", deferred.verb)
        if deferred.verb == "stop":
            self._do_stop()
        elif deferred.verb == "reset":
            self._do_reset()
        elif deferred.verb == "replace":
            self._do_replace(list(deferred.entries))
        elif deferred.verb == "pause_direct" and deferred.routine is not None and self._routine is None:
            self._start_routine(deferred.routine, continuing=self._state is QueueState.RUNNING)

    def _do_stop(self) -> None:
        running = self._state is QueueState.RUNNING or self._routine is not None
        self._state = QueueState.STOPPED
        self._routine = None
        self._pending_pause = None
        if running and self._exec is not None:
            self._emit(EventKind.STOPPED, self._current_entry(), self._index)
        log.info("stopped at command %d", self._index)

    def _do_reset(self) -> None:
        for i in range(self._index, len(self._commands)):
            self._emit(EventKind.CANCELLED, self._commands[i], i, "reset")
        self._commands.clear()
        self._index = 0
        self._exec = None
        self._routine = None
        self._pending_pause = None
        self._takeoff.deferred = None
        self._failure = None
        self._state = QueueState.STOPPED
        self._generation += 1
        self._emit(EventKind.RESET, None, None, f"generation {self._generation}")
        log.info("queue reset (generation %d)", self._generation)

    def _active_execution(self) -> CommandExecution | None:
        if self._routine is not None:
            return self._routine.execution
        if self._state is QueueState.RUNNING:
            return self._exec
        return None

    def _maybe_start(self) -> None:
        """Create the execution of whatever should run now, from the current reference (none yet: later)."""
        if self._ref is None:
            return
        if self._routine is not None:
            if self._routine.execution is None:
                cmd = self._routine.routine.commands[self._routine.index]
                self._routine.execution = CommandExecution(cmd, self._ref, self.limits)
            return
        if self._state is QueueState.RUNNING and self._exec is None and self._index < len(self._commands):
            entry = self._commands[self._index]
            self._exec = CommandExecution(entry.command, self._ref, self.limits)
            self._emit(EventKind.STARTED, entry, self._index)  # an execution is created once per start
            log.info("command %d (id %d) started", self._index, entry.id)

    def _start_routine(self, routine: PauseRoutine, *, continuing: bool) -> None:
        self._pending_pause = None
        self._routine = _ActiveRoutine(routine, 0, None, continuing)
        entry = self._current_entry()
        if entry is not None:
            self._emit(EventKind.PAUSED, entry, self._index, routine.id)
        self._maybe_start()
        log.info("pause routine %s started (%s afterwards)", routine.id,
                 "continue" if continuing else "stop")

    def _finish_active(self) -> None:
        """The active execution's end condition holds: advance (Sec. IV-B sequencing)."""
        b = self._routine
        if b is not None:
            b.index += 1
            b.execution = None
            if b.index < len(b.routine.commands):
                self._maybe_start()
                return
            log.info("pause routine %s finished", b.routine.id)
            self._routine = None
            self._state = QueueState.RUNNING if b.continuing else QueueState.STOPPED
            if b.continuing and self._current_entry() is not None:
                if self._exec is not None and self._ref is not None:
                    self._exec.resume(self._ref)
                self._emit(EventKind.RESUMED, self._current_entry(), self._index, b.routine.id)
            self._maybe_start()
            return
        entry = self._current_entry()
        log.info("command %d finished", self._index)
        if entry is not None:
            self._emit(EventKind.FINISHED, entry, self._index)
        self._exec = None
        self._index += 1
        if self._pending_pause is not None:
            self._start_routine(self._pending_pause, continuing=True)
        else:
            self._maybe_start()

    def _queue_state(self) -> QueueState:
        if self._routine is not None:
            return (QueueState.WAITING_FOR_BEHAVIOR_AND_CONTINUING if self._routine.continuing
                    else QueueState.WAITING_FOR_BEHAVIOR_AND_STOPPING)
        return self._state

    def _command_status(self) -> CommandStatus:
        if self._index >= len(self._commands):
            return CommandStatus.UNKNOWN
        if self._routine is not None:
            return CommandStatus.PAUSED
        if self._failure is not None:
            return CommandStatus.FAILED
        return CommandStatus.RUNNING if self._state is QueueState.RUNNING else CommandStatus.STOPPED

    def _setpoint(self, execution: CommandExecution | None, land_now: bool) -> Setpoint:
        assert self._ref is not None
        routine_id = self._routine.routine.id if self._routine is not None else None
        own = execution is not None and routine_id is None  # a command of the list, not of a routine
        entry = self._current_entry() if own else None
        return streamed_setpoint(self._ref, execution, land_now, index=self._index if own else None,
                                 command_id=entry.id if entry else None, routine_id=routine_id)
