"""The control surface's request and answer models (pydantic): one per body and answer, so the OpenAPI
document of :mod:`companion.http` is complete. The status and event answers derive from the
queue's dataclasses (:class:`~companion.flight.qapi.QueueStatus`,
:class:`~companion.flight.events.QueueEvent`).
"""

from __future__ import annotations

import dataclasses
import typing
from typing import TYPE_CHECKING, Annotated, Any

from pydantic import AllowInfNan, BaseModel, ConfigDict, Discriminator, Field, Strict, Tag, create_model

from companion.flight import FlightCommand, QueueEvent, QueueStatus, command_from_dict

Number = Annotated[float, Strict(), AllowInfNan(False)]


# --- models: requests ------------------------------------------------------------------------------
_CHANNEL_DOC = ("A channel in the flight codec's form: ``mode`` and that mode's parameters "
                "(:mod:`companion.flight.commands`). Missing or null: DNU.")

_COMMAND_EXAMPLES: Any = [
    {"vertical": {"mode": "POS", "altitude": 5, "take_off": True}, "end": {"e_v": True}},
    {"horizontal": {"mode": "POS", "north": 10, "east": 5, "speed": 3, "speed_modified_by": ["vertical"]},
     "vertical": {"mode": "POS", "altitude": 10, "frame": "relative"},
     "heading": {"mode": "POINT", "north": 0, "east": 0},
     "end": {"e_h": True, "e_v": True}},
]


class FlightCommandModel(BaseModel):
    """A flight command (seed 000 Sec. IV-A) in the flight codec's form (:mod:`companion.flight.codec`).

    The channels and the end condition are validated by the codec (modes, parameters, frames, an end
    condition that can be reached); an error names the offending field.
    """

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": _COMMAND_EXAMPLES})

    horizontal: dict[str, Any] | None = Field(
        None, description=_CHANNEL_DOC + " Modes: POS, EXT_POS, KEEP_DISTANCE, EXT_VEL, RC_VEL, DNU.",
        examples=[{"mode": "POS", "north": 10, "east": 5, "frame": "absolute", "speed": 3}])
    vertical: dict[str, Any] | None = Field(
        None, description=_CHANNEL_DOC + " Modes: POS, WITH_HOR, EXT_POS, EXT_VEL, RC_VEL, DNU.",
        examples=[{"mode": "POS", "altitude": 5, "take_off": True}])
    heading: dict[str, Any] | None = Field(
        None, description=_CHANNEL_DOC + " Modes: POS, FLIGHT_DIR, EXT_POS, EXT_VEL, RC_VEL, POINT, "
        "EXT_POINT, DNU.", examples=[{"mode": "POS", "heading": 90, "rate": 30}])
    end: dict[str, Any] = Field(
        description="The end condition (Fig. 8): flags ``e_h``, ``e_v``, ``e_hd``, ``e_any``, ``e_user`` "
        "and ``e_wait`` (s).", examples=[{"e_h": True, "e_v": True}])

    def to_command(self, prefix: str = "") -> FlightCommand:
        """The validated command; :class:`ConfigError` naming the field (``prefix.field``) otherwise."""
        return command_from_dict(self.model_dump(exclude_none=True), file="<request>", prefix=prefix)


class CommandBatch(BaseModel):
    """Several flight commands, added atomically (all checked first; all or none)."""

    model_config = ConfigDict(extra="forbid")

    commands: list[FlightCommandModel] = Field(min_length=1)


def _command_or_batch(value: Any) -> str:
    return "batch" if isinstance(value, dict) and "commands" in value else "command"


#: the union tags pydantic puts into an error's location (left out of the messages)
UNION_TAGS = frozenset({"batch", "command"})

CommandsBody = Annotated[
    Annotated[CommandBatch, Tag("batch")] | Annotated[FlightCommandModel, Tag("command")],
    Discriminator(_command_or_batch),
]


class PauseRequest(BaseModel):
    """The pause routine to run (default ``hover``)."""

    model_config = ConfigDict(extra="forbid")

    routine_id: str | None = Field(None, description="an id of ``GET /pause_routines``", examples=["hover"])


class ExternalSample(BaseModel):
    """An external-data sample (Sec. IV-C), stamped with the queue's clock: on arrival, minus ``age_ms``
    (how old it already was when sent, e.g. an operator's stick sample forwarded by the ground service).
    A sample already past its validity, or with a ``seq`` not above its ``sender``'s last, is dropped
    (``accepted: false`` with the reason)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [
        {"values": [1.0, 0.0, 0.0, 0.0], "validity_s": 0.5},
        {"values": [1.0, 0.0, 0.0, 0.0], "validity_s": 0.3, "age_ms": 40, "seq": 17,
         "sender": "lease-1f2e"}]})

    values: list[Number] = Field(description="the stream's values: ext_pos 3 (north, east, down), ext_vel 4 "
                                 "(vn, ve, vd, yaw rate), ext_heading 1, ext_point 2, rc_vel 4")
    validity_s: Number = Field(0.5, gt=0, description="how long the sample stays fresh (s; at most the "
                               "node's maximum, ``--max-validity``)")
    age_ms: Number = Field(0.0, ge=0, le=60_000, description="how old the sample already is when sent (ms, "
                           "measured by the sender from where it was made); its validity counts from then")
    seq: Annotated[int, Strict()] | None = Field(None, ge=0, description="the sender's sequence number: a "
                                                 "sample not above the last one of its sender is dropped")
    sender: str | None = Field(None, min_length=1, max_length=64,
                               description="who sends (sequence numbers are per sender), e.g. a stick "
                               "lease id")


class RetargetRequest(BaseModel):
    """New targets of the executing command (Sec. IV-D); left out: unchanged."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"north": 12.0, "east": 4.0},
                                                                              {"speed": 2.0}]})

    north: Number | None = Field(None, description="m, local NED, absolute (horizontal POS)")
    east: Number | None = Field(None, description="m, local NED, absolute (horizontal POS)")
    altitude: Number | None = Field(None, description="m up, absolute (vertical POS or WITH_HOR)")
    speed: Number | None = Field(None, description="m/s (horizontal POS, EXT_POS, KEEP_DISTANCE)")
    heading: Number | None = Field(None, description="degrees, absolute (heading POS)")


# --- models: answers -------------------------------------------------------------------------------
def _model_of(cls: type, doc: str) -> type[BaseModel]:
    """A pydantic model with the fields of the dataclass ``cls`` (one definition of each answer)."""
    hints = typing.get_type_hints(cls)
    spec: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        default = f.default if f.default is not dataclasses.MISSING else ...
        spec[f.name] = (hints[f.name], default)
    model = create_model(cls.__name__ + "Model", __doc__=doc, **spec)
    return model


if TYPE_CHECKING:  # made from the dataclass at run time; a pydantic model to the type checker
    class QueueStatusModel(BaseModel): ...

    class EventModel(BaseModel): ...
else:
    #: The QAPI status (Sec. V): the paper's fields, then ours (:class:`companion.flight.qapi.QueueStatus`).
    QueueStatusModel = _model_of(QueueStatus, "The QAPI status (Sec. V): the paper's fields, then ours.")
    #: One queue event (:class:`companion.flight.events.QueueEvent`).
    EventModel = _model_of(QueueEvent, "One queue event (companion.flight.events.QueueEvent).")


class NodeInfo(BaseModel):
    """What the node's tick thread does."""

    rate_hz: float
    ticks: int
    streamed: int
    resyncs: int
    queue_time_s: float
    last_setpoint: dict[str, Any] | None


class StatusResponse(BaseModel):
    """``GET /status``."""

    queue: QueueStatusModel
    commands: int = Field(description="how many commands the list holds")
    routine_id: str | None = Field(description="the pause routine running, if any")
    flight: dict[str, Any] = Field(description="the GUIDED supervisor: phase, take-off, override")
    link: dict[str, Any] = Field(description="the MAVLink link: connection, clock, statistics")
    vehicle: dict[str, Any] = Field(description="the mirrored vehicle state")
    node: NodeInfo
    awaits_operator: bool | None = Field(
        None, description="the command waits for the operator's confirmation because someone asked for "
                          "it (not an idle vehicle's default hover); when the executive layer is served")


class CommandEntry(BaseModel):
    id: int = Field(description="the process-unique command id")
    index: int = Field(description="its position in the list")
    command: FlightCommandModel


class CommandListResponse(BaseModel):
    """``GET /commands``."""

    commands: list[CommandEntry]
    current_command_index: int
    current_command_id: int | None
    generation: int


class AddedResponse(BaseModel):
    """``POST /commands``: the new commands' ids and positions (null: a reset has dropped it already)."""

    ids: list[int]
    indices: list[int | None]
    activation_id: str | None = Field(None, description="with the executive layer on: the FLY_COMMANDS "
                                                         "activation flying them")


class VerbResponse(BaseModel):
    ok: bool = True
    status: QueueStatusModel


class PauseRoutinesResponse(BaseModel):
    pause_routines: list[str]


class AcceptedResponse(BaseModel):
    accepted: bool = Field(description="false: dropped (older than the stream's newest sample, stale on "
                           "arrival, or out of order)")
    reason: str | None = Field(None, description="why it was dropped (null when accepted)")



class EventsResponse(BaseModel):
    """``GET /events``: poll again with ``since=last_seq``."""

    events: list[EventModel]
    last_seq: int


class EventWaitResponse(BaseModel):
    """``GET /events/wait``: the event, or null when the deadline passed."""

    event: EventModel | None


