"""The QAPI (seed 000 Sec. V): what :class:`~.queue.CommandQueue`'s verbs do, its status and errors.

Verbs (Sec. V) and the decisions where the paper is silent
    ``add_command(c) -> id``  append (validated; an absolute target outside the envelope is
        refused). If the queue is running and idle, the command starts at the next tick. Ids are
        unique for the life of the process (never reused after ``reset()``).
    ``add_commands([c, ...]) -> [id, ...]``  all validated first, then appended at once (atomic:
        all or none, no tick in between).
    ``check_command(c)``  raise what ``add_command(c)`` would, change nothing.
    ``replace_commands([c, ...]) -> [id, ...]``  ``reset()``, ``add_commands`` and ``run()`` at once
        (no tick in between): the behaviors' way to switch maneuvers (seed 001); deferred like
        ``reset`` during a take-off that may not be stopped yet.
    ``run()``  start or continue; also before anything is queued (execution starts with the first
        command added). A stopped command is resumed (see below). Called during a pause routine,
        it abandons the routine and continues at once ("pause_direct, then run again").
        Idempotent when already running. Clears a failure (the failed command is tried again).
    ``stop()``  do not advance; the current command (or pause routine) stops at once **if
        allowed** and the reference comes to rest where it is, smoothly. ``run()`` resumes it.
    ``pause_direct(routine_id=None)``  interrupt now and run a pause routine (default
        ``hover``). When it finishes the interrupted command is **resumed** from the current
        reference: resolved targets kept (a relative waypoint stays where it was), time already
        waited and a given confirmation kept, trajectory replanned. Refused while a routine is
        running. Cancels a pending ``pause_after_current``. Allowed while stopped: the routine
        runs and the queue stays stopped afterwards (WAITING_FOR_BEHAVIOR_AND_STOPPING).
    ``pause_after_current(routine_id=None)``  when the current command ends, run the routine,
        then continue with the next command. With nothing executing it acts as ``pause_direct``.
        Refused while a routine runs or another pause is pending.
    ``reset()``  clear the list, drop any routine, hold where the reference is; the queue is
        STOPPED afterwards (commands added later wait for ``run()``), the index restarts at 0 and
        the ``generation`` goes up by one. Unfinished commands get a CANCELLED event.
    ``user_confirm()``  the E_User confirmation of the executing command (or routine command);
        :class:`QueueStateError` when nothing is waiting for one (nothing changes).
    ``retarget(id, north=, east=, altitude=, speed=, heading=)``  change the running command's
        target in flight (Sec. IV-D, :mod:`.retarget`); the stream stays continuous.
    A verb in the wrong state raises :class:`QueueStateError`, an unknown routine
    :class:`QueueError`, and changes nothing. While OVERRIDDEN only ``add_command``, ``stop``,
    ``reset`` are accepted.

Tick contract (the link's side)
    ``tick(now_s, vehicle_state, follow_vehicle=False) -> Setpoint | None``. ``now_s`` is the
    companion's clock (the autopilot's time); ``vehicle_state`` is required on the first tick (the
    reference starts at the measured state) and after an override. With ``follow_vehicle`` (the
    link is not streaming) and nothing executing, the reference is re-anchored on the measured
    state, so the next command starts where the vehicle is. The setpoint is the reference one tick
    ahead. A tick with ``now_s`` not after the previous one returns the previous setpoint. Intervals
    above ``max_step_s`` (1 s) advance the reference by ``max_step_s`` only (a stalled loop never
    makes the reference leap); shorter ones in full, so that after a late tick the reference is
    where the autopilot, which carries the last setpoint on with its velocity (ArduCopter's GUIDED
    until GUID_TIMEOUT, 3 s), expects it, instead of falling behind the vehicle for the rest of the
    flight. Returns None while OVERRIDDEN.

Status (Sec. V, :class:`QueueStatus`)
    ``queue_system_status`` RUNNING / OVERRIDDEN (someone else took the vehicle: ``set_overridden``,
    called by the link on a mode change or disarm; the queue then stops and ``tick`` returns None;
    when given back, the reference restarts from the measured state and the queue waits for run()).
    ``queue_status`` STOPPED / RUNNING / WAITING_FOR_BEHAVIOR_AND_STOPPING /
    WAITING_FOR_BEHAVIOR_AND_CONTINUING (what the queue does once the routine finishes).
    ``current_command_index`` the command executing, or the one that starts on run(); equals the
    number of commands when all are done. ``current_command_status`` UNKNOWN (no command at the
    index) / STOPPED / RUNNING / PAUSED (a pause routine runs before it resumes or starts) /
    FAILED (the link gave it up, e.g. a refused take-off; ``failure`` says why).
    ``confirmation_required_status``, ``limit_reached``, ``target_position_unreachable`` (of the
    last tick), ``is_synced`` (set by the link from the autopilot's POSITION_TARGET_LOCAL_NED echo).
    Beyond the paper: ``current_command_id``, ``generation``, ``failure``, ``deferred``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from enum import Enum

from .commands import FlightCommand


class QueueError(ValueError):
    """A verb's argument is wrong (unknown routine, not a flight command); nothing changed."""


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
    """Values of ``current_command_status`` (Sec. V; FAILED is ours: the link gave the command up)."""

    UNKNOWN = "UNKNOWN"
    STOPPED = "STOPPED"
    RUNNING = "RUNNING"
    PAUSED = "PAUSED"
    FAILED = "FAILED"


@dataclass(frozen=True)
class QueueStatus:
    """A snapshot of the QAPI status (Sec. V): the paper's fields, then ours (see module docstring)."""

    queue_system_status: QueueSystemStatus
    queue_status: QueueState
    current_command_index: int
    current_command_status: CommandStatus
    confirmation_required_status: bool
    limit_reached: bool
    target_position_unreachable: bool
    is_synced: bool
    current_command_id: int | None = None
    generation: int = 0
    failure: str | None = None
    deferred: str | None = None

    def to_dict(self) -> dict[str, object]:
        out = asdict(self)
        for key, value in out.items():
            if isinstance(value, Enum):
                out[key] = value.name
        return out


@dataclass
class QueuedCommand:
    """One entry of the list: the command and its process-unique id."""

    id: int
    command: FlightCommand
