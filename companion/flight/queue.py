"""The flight command queue with the QAPI verbs and status (seed 000 Sec. IV-B and Sec. V).

:class:`CommandQueue` holds the list of flight commands and executes them in sequence; its owner (the
MAVLink link) calls :meth:`CommandQueue.tick` at the streaming rate with the time and the measured
vehicle state and streams the returned :class:`~companion.flight.setpoint.Setpoint`. Other threads
(the HTTP control surface, behaviours) call the verbs. One lock guards all state; only the queue's
own methods change it (one writer).

Verbs (Sec. V) and the decisions where the paper is silent
    ``add_command(c) -> index``  append (validated; an absolute target outside the envelope is
        refused). If the queue is running and idle, the command starts at the next tick.
    ``check_command(c)``  raise what ``add_command(c)`` would, change nothing (all-or-none batches).
    ``run()``  start or continue; also before anything is queued (execution starts with the first
        command added). A stopped command is resumed (see below). Called during a pause behaviour,
        it abandons the behaviour and continues at once ("pause_direct, then run again").
        Idempotent when already running.
    ``stop()``  do not advance; the current command (or pause behaviour) stops at once and the
        reference comes to rest where it is, smoothly. ``run()`` resumes the stopped command.
    ``pause_direct(behaviour_id=None)``  interrupt now and run a pause behaviour (default
        ``hover``). When it finishes the interrupted command is **resumed** from the current
        reference: resolved targets kept (a relative waypoint stays where it was), time already
        waited and a given confirmation kept, trajectory replanned. Refused while a behaviour is
        running. Cancels a pending ``pause_after_current``. Allowed while stopped: the behaviour
        runs and the queue stays stopped afterwards (WAITING_FOR_BEHAVIOR_AND_STOPPING).
    ``pause_after_current(behaviour_id=None)``  when the current command ends, run the behaviour,
        then continue with the next command. With nothing executing it acts as ``pause_direct``.
        Refused while a behaviour runs or another pause is pending.
    ``reset()``  clear the list, drop any behaviour, hold where the reference is; the queue is
        STOPPED afterwards (commands added later wait for ``run()``), the index restarts at 0.
    ``user_confirm()``  the E_User confirmation of the executing command (or behaviour command);
        :class:`QueueStateError` when nothing is waiting for one (nothing changes).
    A verb in the wrong state raises :class:`QueueStateError`, an unknown behaviour
    :class:`QueueError`, and changes nothing. While OVERRIDDEN only ``add_command``, ``stop``,
    ``reset`` are accepted.

Status (Sec. V, :class:`QueueStatus`)
    ``queue_system_status`` RUNNING / OVERRIDDEN (someone else took the vehicle: ``set_overridden``,
    called by the link on a mode change or disarm; the queue then stops and ``tick`` returns None;
    when given back, the reference restarts from the measured state and the queue waits for run()).
    ``queue_status`` STOPPED / RUNNING / WAITING_FOR_BEHAVIOR_AND_STOPPING /
    WAITING_FOR_BEHAVIOR_AND_CONTINUING (what the queue does once the behaviour finishes).
    ``current_command_index`` the command executing, or the one that starts on run(); equals the
    number of commands when all are done. ``current_command_status`` UNKNOWN (no command at the
    index) / STOPPED / RUNNING / PAUSED (a pause behaviour runs before it resumes or starts).
    ``confirmation_required_status``, ``limit_reached``, ``target_position_unreachable`` (of the
    last tick), ``is_synced`` (set by the link from the autopilot's POSITION_TARGET_LOCAL_NED echo).

Tick contract
    ``tick(now_s, vehicle_state) -> Setpoint | None``. ``now_s`` is the companion's clock (the
    autopilot's time); ``vehicle_state`` is required on the first tick (the reference starts at the
    measured state) and after an override. The setpoint is the reference one tick ahead. A tick
    with ``now_s`` not after the previous one returns the previous setpoint. Intervals above
    ``max_step_s`` advance the reference by ``max_step_s`` only (a stalled loop never makes the
    reference leap). Returns None while OVERRIDDEN.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from enum import Enum

from taskflight.clock import Clock

from .behaviours import DEFAULT_BEHAVIOUR, BehaviourCatalog, PauseBehaviour, default_catalog
from .commands import CommandError, FlightCommand, Frame, HorizontalMode, VerticalMode
from .execution import CommandExecution
from .external import ExternalData, Sample
from .limits import Envelope, Limits
from .reference import HOLD, Reference, ReferenceGenerator, wrap_pi
from .setpoint import Setpoint, SetpointKind, VehicleState

log = logging.getLogger(__name__)


class QueueError(ValueError):
    """A verb's argument is wrong (unknown behaviour, not a flight command); nothing changed."""


class QueueStateError(QueueError):
    """A verb is not allowed in the queue's current state; nothing changed."""


class QueueSystemStatus(Enum):
    RUNNING = "RUNNING"
    OVERRIDDEN = "OVERRIDDEN"


class QueueState(Enum):
    """Values of ``queue_status`` (Sec. V)."""

    STOPPED = "STOPPED"
    RUNNING = "RUNNING"
    WAITING_FOR_BEHAVIOR_AND_STOPPING = "WAITING_FOR_BEHAVIOR_AND_STOPPING"
    WAITING_FOR_BEHAVIOR_AND_CONTINUING = "WAITING_FOR_BEHAVIOR_AND_CONTINUING"


class CommandStatus(Enum):
    """Values of ``current_command_status`` (Sec. V)."""

    UNKNOWN = "UNKNOWN"
    STOPPED = "STOPPED"
    RUNNING = "RUNNING"
    PAUSED = "PAUSED"


@dataclass(frozen=True)
class QueueStatus:
    """A snapshot of the QAPI status (Sec. V), exactly its fields."""

    queue_system_status: QueueSystemStatus
    queue_status: QueueState
    current_command_index: int
    current_command_status: CommandStatus
    confirmation_required_status: bool
    limit_reached: bool
    target_position_unreachable: bool
    is_synced: bool

    def to_dict(self) -> dict[str, object]:
        out = asdict(self)
        for key, value in out.items():
            if isinstance(value, Enum):
                out[key] = value.name
        return out


@dataclass
class _ActiveBehaviour:
    behaviour: PauseBehaviour
    index: int
    execution: CommandExecution | None
    continuing: bool  # what the queue does afterwards: continue (True) or stay stopped


class CommandQueue:
    """The QAPI command queue (see module docstring)."""

    def __init__(self, limits: Limits | None = None, envelope: Envelope | None = None,
                 catalog: BehaviourCatalog | None = None, clock: Clock | None = None,
                 max_step_s: float = 0.25) -> None:
        self.limits = limits or Limits()
        self.envelope = envelope or Envelope()
        self.catalog = catalog or default_catalog()
        self._clock = clock
        self._max_step_s = max_step_s
        self._lock = threading.RLock()
        self._gen = ReferenceGenerator(self.limits, self.envelope)
        self._ext = ExternalData()
        self._commands: list[FlightCommand] = []
        self._index = 0
        self._exec: CommandExecution | None = None
        self._state = QueueState.STOPPED
        self._behaviour: _ActiveBehaviour | None = None
        self._pending_pause: PauseBehaviour | None = None
        self._overridden = False
        self._synced = False
        self._ref: Reference | None = None
        self._last_t: float | None = None
        self._last_setpoint: Setpoint | None = None
        self._limit_reached = False
        self._unreachable = False

    # --- QAPI verbs ----------------------------------------------------------------------------------
    def check_command(self, command: FlightCommand) -> None:
        """Raise what :meth:`add_command` would raise for ``command`` (QueueError, CommandError); no change.

        For an all-or-none batch: check every command first, then add them.
        """
        if not isinstance(command, FlightCommand):
            raise QueueError(f"expected a FlightCommand, got {type(command).__name__}")
        self._check_envelope(command)

    def add_command(self, command: FlightCommand) -> int:
        """Append a command; returns its index."""
        self.check_command(command)
        with self._lock:
            self._commands.append(command)
            index = len(self._commands) - 1
            log.info("command %d added", index)
            self._maybe_start()
            return index

    def run(self) -> None:
        with self._lock:
            self._refuse_if_overridden("run")
            was_running = self._state is QueueState.RUNNING and self._behaviour is None
            if self._behaviour is not None:
                log.info("run(): abandoning pause behaviour %s", self._behaviour.behaviour.id)
                self._behaviour = None
            self._state = QueueState.RUNNING
            if not was_running and self._exec is not None and self._ref is not None:
                self._exec.resume(self._ref)
            self._maybe_start()

    def stop(self) -> None:
        with self._lock:
            self._state = QueueState.STOPPED
            self._behaviour = None
            self._pending_pause = None
            log.info("stopped at command %d", self._index)

    def pause_direct(self, behaviour_id: str | None = None) -> None:
        with self._lock:
            self._refuse_if_overridden("pause_direct")
            behaviour = self._behaviour_of(behaviour_id)
            if self._behaviour is not None:
                raise QueueStateError(f"pause_direct: already in pause behaviour "
                                      f"{self._behaviour.behaviour.id!r} (user_confirm or run() ends it)")
            self._start_behaviour(behaviour, continuing=self._state is QueueState.RUNNING)

    def pause_after_current(self, behaviour_id: str | None = None) -> None:
        with self._lock:
            self._refuse_if_overridden("pause_after_current")
            behaviour = self._behaviour_of(behaviour_id)
            if self._behaviour is not None:
                raise QueueStateError(f"pause_after_current: already in pause behaviour "
                                      f"{self._behaviour.behaviour.id!r}")
            if self._pending_pause is not None:
                raise QueueStateError(f"pause_after_current: pause {self._pending_pause.id!r} "
                                      "already pending")
            if self._state is QueueState.RUNNING and self._index < len(self._commands):
                self._pending_pause = behaviour
                log.info("pause %s after command %d", behaviour.id, self._index)
            else:
                self._start_behaviour(behaviour, continuing=self._state is QueueState.RUNNING)

    def reset(self) -> None:
        with self._lock:
            self._commands.clear()
            self._index = 0
            self._exec = None
            self._behaviour = None
            self._pending_pause = None
            self._state = QueueState.STOPPED
            log.info("queue reset")

    def user_confirm(self) -> None:
        with self._lock:
            self._refuse_if_overridden("user_confirm")
            execution = self._active_execution()
            if execution is None or not execution.waiting_for_confirmation:
                what = "no command is executing" if execution is None else "the executing command does not " \
                    "wait for a user confirmation"
                raise QueueStateError(f"user_confirm: nothing is waiting for a confirmation ({what})")
            execution.confirm()
            if execution.ended:
                self._finish_active()

    # --- link side ------------------------------------------------------------------------------------
    def set_overridden(self, overridden: bool) -> None:
        """Called by the link: someone else took the vehicle (mode change, disarm) or gave it back."""
        with self._lock:
            if overridden and not self._overridden:
                log.warning("queue overridden: stopping, no more setpoints")
                self._state = QueueState.STOPPED
                self._behaviour = None
                self._pending_pause = None
                self._ref = None
                self._last_setpoint = None
            self._overridden = bool(overridden)

    def set_synced(self, synced: bool) -> None:
        """Called by the link: the autopilot's POSITION_TARGET_LOCAL_NED echoes what we stream."""
        with self._lock:
            self._synced = bool(synced)

    def push_external(self, stream: str, values: Sequence[float], validity_s: float,
                      t_s: float | None = None) -> bool:
        """Store an external-data sample (Sec. IV-C); stamped with the clock (or the last tick) if no ``t_s``.

        Raises :class:`~companion.flight.external.ExternalDataError` when malformed (nothing changes).
        """
        with self._lock:
            if t_s is None:
                t_s = self._clock.now() if self._clock is not None else (self._last_t or 0.0)
            return self._ext.push(stream, values, validity_s, t_s)

    def external_sample(self, stream: str) -> Sample | None:
        """The newest sample of an external stream, fresh or not (read-only view)."""
        with self._lock:
            return self._ext.sample(stream)

    # --- status ------------------------------------------------------------------------------------------
    def status(self) -> QueueStatus:
        with self._lock:
            execution = self._active_execution()
            return QueueStatus(
                queue_system_status=(QueueSystemStatus.OVERRIDDEN if self._overridden
                                     else QueueSystemStatus.RUNNING),
                queue_status=self._queue_state(),
                current_command_index=self._index,
                current_command_status=self._command_status(),
                confirmation_required_status=execution is not None and execution.waiting_for_confirmation,
                limit_reached=self._limit_reached,
                target_position_unreachable=self._unreachable,
                is_synced=self._synced)

    @property
    def commands(self) -> tuple[FlightCommand, ...]:
        with self._lock:
            return tuple(self._commands)

    @property
    def behaviour_id(self) -> str | None:
        """The pause behaviour running, if any."""
        with self._lock:
            return self._behaviour.behaviour.id if self._behaviour else None

    @property
    def reference(self) -> Reference | None:
        with self._lock:
            return self._ref

    @property
    def guard_interventions(self) -> int:
        return self._gen.guard_interventions

    # --- the tick ----------------------------------------------------------------------------------------
    def tick(self, now_s: float, vehicle_state: VehicleState | None = None) -> Setpoint | None:
        """Advance to ``now_s`` and return the setpoint to stream (see module docstring)."""
        with self._lock:
            if self._overridden:
                return None
            if self._ref is None:
                if vehicle_state is None:
                    raise ValueError("tick: the first tick (and the first after an override) needs "
                                     "the vehicle state")
                self._ref = self._gen.initial(now_s, vehicle_state.p, vehicle_state.v, vehicle_state.yaw)
                self._last_t = now_s
                self._last_setpoint = self._setpoint(None, False)
                return self._last_setpoint
            assert self._last_t is not None
            elapsed = now_s - self._last_t
            if elapsed <= 0 and self._last_setpoint is not None:
                return self._last_setpoint
            self._last_t = now_s
            dt = min(elapsed, self._max_step_s)
            self._maybe_start()
            execution = self._active_execution()
            land_now = False
            if execution is None:
                result = self._gen.step(self._ref, HOLD, dt)
            else:
                outcome = execution.step(self._ref, dt, elapsed, now_s, self._ext, self._gen, vehicle_state)
                result = outcome.step
                land_now = outcome.land_now
            self._ref = replace(result.reference, t_s=now_s)
            self._limit_reached = result.limit_reached
            self._unreachable = result.target_unreachable
            setpoint = self._setpoint(execution, land_now)
            if execution is not None and execution.ended:
                self._finish_active()
            self._last_setpoint = setpoint
            return setpoint

    # --- internals (call with the lock held) ------------------------------------------------------------
    def _refuse_if_overridden(self, verb: str) -> None:
        if self._overridden:
            raise QueueStateError(f"{verb}: the queue is OVERRIDDEN (the vehicle is controlled elsewhere)")

    def _behaviour_of(self, behaviour_id: str | None) -> PauseBehaviour:
        bid = DEFAULT_BEHAVIOUR if behaviour_id is None else behaviour_id
        try:
            return self.catalog.get(bid)
        except KeyError as exc:
            raise QueueError(str(exc.args[0])) from None

    def _check_envelope(self, command: FlightCommand) -> None:
        h, v = command.horizontal, command.vertical
        if h.mode is HorizontalMode.POS and h.resolved_frame is Frame.ABSOLUTE \
                and not self.envelope.contains_ne((h.north, h.east)):  # type: ignore[arg-type]
                raise CommandError("horizontal.north", f"target ({h.north:g}, {h.east:g}) lies outside the "
                                                       "operational envelope")
        absolute_alt = v.mode is VerticalMode.WITH_HOR or (v.mode is VerticalMode.POS
                                                            and v.resolved_frame is Frame.ABSOLUTE)
        if absolute_alt and v.altitude is not None:
            _, moved = self.envelope.clamp_altitude(v.altitude, floor_exempt=v.take_off or v.allow_landing)
            if moved:
                raise CommandError("vertical.altitude",
                                   f"altitude {v.altitude:g} m lies outside the operational envelope")

    def _active_execution(self) -> CommandExecution | None:
        if self._behaviour is not None:
            return self._behaviour.execution
        if self._state is QueueState.RUNNING:
            return self._exec
        return None

    def _maybe_start(self) -> None:
        """Create the execution of whatever should run now, from the current reference (none yet: later)."""
        if self._ref is None:
            return
        if self._behaviour is not None:
            if self._behaviour.execution is None:
                cmd = self._behaviour.behaviour.commands[self._behaviour.index]
                self._behaviour.execution = CommandExecution(cmd, self._ref, self.limits)
            return
        if self._state is QueueState.RUNNING and self._exec is None and self._index < len(self._commands):
            self._exec = CommandExecution(self._commands[self._index], self._ref, self.limits)
            log.info("command %d started", self._index)

    def _start_behaviour(self, behaviour: PauseBehaviour, *, continuing: bool) -> None:
        self._pending_pause = None
        self._behaviour = _ActiveBehaviour(behaviour, 0, None, continuing)
        self._maybe_start()
        log.info("pause behaviour %s started (%s afterwards)", behaviour.id,
                 "continue" if continuing else "stop")

    def _finish_active(self) -> None:
        """The active execution's end condition holds: advance (Sec. IV-B sequencing)."""
        b = self._behaviour
        if b is not None:
            b.index += 1
            b.execution = None
            if b.index < len(b.behaviour.commands):
                self._maybe_start()
                return
            log.info("pause behaviour %s finished", b.behaviour.id)
            self._behaviour = None
            self._state = QueueState.RUNNING if b.continuing else QueueState.STOPPED
            if b.continuing and self._exec is not None and self._ref is not None:
                self._exec.resume(self._ref)
            self._maybe_start()
            return
        log.info("command %d finished", self._index)
        self._exec = None
        self._index += 1
        if self._pending_pause is not None:
            self._start_behaviour(self._pending_pause, continuing=True)
        else:
            self._maybe_start()

    def _queue_state(self) -> QueueState:
        if self._behaviour is not None:
            return (QueueState.WAITING_FOR_BEHAVIOR_AND_CONTINUING if self._behaviour.continuing
                    else QueueState.WAITING_FOR_BEHAVIOR_AND_STOPPING)
        return self._state

    def _command_status(self) -> CommandStatus:
        if self._index >= len(self._commands):
            return CommandStatus.UNKNOWN
        if self._behaviour is not None:
            return CommandStatus.PAUSED
        return CommandStatus.RUNNING if self._state is QueueState.RUNNING else CommandStatus.STOPPED

    def _setpoint(self, execution: CommandExecution | None, land_now: bool) -> Setpoint:
        ref = self._ref
        assert ref is not None
        kind = SetpointKind.POSITION
        take_off = allow_landing = False
        takeoff_alt = None
        index: int | None = None
        behaviour_id = self._behaviour.behaviour.id if self._behaviour is not None else None
        if execution is not None:
            cmd = execution.command
            if cmd.velocity_only:
                kind = SetpointKind.VELOCITY
            take_off = cmd.vertical.take_off
            allow_landing = cmd.vertical.allow_landing
            if take_off and execution.v_target_down is not None:
                takeoff_alt = -execution.v_target_down
            if behaviour_id is None:
                index = self._index
        return Setpoint(ref.t_s, ref.p, ref.v, ref.a, wrap_pi(ref.yaw), ref.yaw_rate, kind, take_off,
                        takeoff_alt, allow_landing, land_now, index, behaviour_id)
