"""The companion's flight layer (seed 000 Sec. IV and V): flight commands, reference generation,
external data and the command queue with the QAPI verbs. Pure logic: the MAVLink link
(``companion/link/``) ticks the queue and streams its setpoints.
"""

from .codec import (
    command_from_dict,
    command_from_json,
    command_from_yaml,
    command_to_dict,
    command_to_json,
    commands_from_json,
    commands_from_yaml,
    commands_to_json,
    commands_to_yaml,
    load_commands,
)
from .commands import (
    CommandError,
    EndCondition,
    FlightCommand,
    Frame,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    SpeedModifier,
    VerticalChannel,
    VerticalMode,
)
from .events import EventKind, EventLog, QueueEvent
from .external import STREAMS, ExternalData, ExternalDataError
from .limits import Envelope, Limits, load_flight_config
from .pause_routines import PauseRoutine, PauseRoutineCatalog, default_catalog, load_catalog
from .qapi import QueuedCommand
from .queue import (
    CommandQueue,
    CommandStatus,
    QueueError,
    QueueState,
    QueueStateError,
    QueueStatus,
    QueueSystemStatus,
)
from .reference import Reference, ReferenceGenerator
from .retarget import Retarget
from .setpoint import Setpoint, SetpointKind, VehicleState

__all__ = [
    "STREAMS",
    "CommandError",
    "CommandQueue",
    "CommandStatus",
    "EndCondition",
    "Envelope",
    "EventKind",
    "EventLog",
    "ExternalData",
    "ExternalDataError",
    "FlightCommand",
    "Frame",
    "HeadingChannel",
    "HeadingMode",
    "HorizontalChannel",
    "HorizontalMode",
    "Limits",
    "PauseRoutine",
    "PauseRoutineCatalog",
    "QueueError",
    "QueueEvent",
    "QueueState",
    "QueueStateError",
    "QueueStatus",
    "QueueSystemStatus",
    "QueuedCommand",
    "Reference",
    "ReferenceGenerator",
    "Retarget",
    "Setpoint",
    "SetpointKind",
    "SpeedModifier",
    "VehicleState",
    "VerticalChannel",
    "VerticalMode",
    "command_from_dict",
    "command_from_json",
    "command_from_yaml",
    "command_to_dict",
    "command_to_json",
    "commands_from_json",
    "commands_from_yaml",
    "commands_to_json",
    "commands_to_yaml",
    "default_catalog",
    "load_catalog",
    "load_commands",
    "load_flight_config",
]
