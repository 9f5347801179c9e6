"""The QAPI's status and errors (seed 000 Sec. V): the values :class:`~.queue.CommandQueue` reports."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from enum import Enum

from .commands import FlightCommand


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
