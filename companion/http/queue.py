"""The command queue's QAPI (seed 000 Sec. IV, V): the command list, the verbs, retargeting in flight
and the external-data streams.

=========================================  ===========================================================
``GET  /commands``                         the queued commands ``[{id, index, command}]``, the current
                                           index and id, the queue's generation
``POST /commands``                         one command ``{horizontal, vertical, heading, end}``, or
                                           ``{"commands": [...]}``; atomic (all checked first, then all
                                           added, or none) -> ``{"ids": [...], "indices": [...]}``
``POST /commands/{command_id}/retarget``   change the executing command's target in flight (Sec. IV-D)
                                           ``{north, east, altitude, speed, heading}`` (all optional)
                                           -> the command as it now reads
``POST /run``, ``/stop``, ``/reset``,      the verbs -> ``{"ok": true, "status": {...}}``
``/user_confirm``
``POST /external/{stream}``                an external-data sample ``{"values": [...], "validity_s": 0.5}``
                                           (streams: ext_pos, ext_vel, ext_heading, ext_point, rc_vel)
=========================================  ===========================================================
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any

from fastapi import APIRouter, Body, Path

from companion.flight import (
    STREAMS,
    CommandError,
    ExternalDataError,
    QueueError,
    QueueStateError,
    Retarget,
    command_to_dict,
)
from companion.http.models import (
    AcceptedResponse,
    AddedResponse,
    CommandBatch,
    CommandEntry,
    CommandListResponse,
    CommandsBody,
    ExternalSample,
    FlightCommandModel,
    QueueStatusModel,
    RetargetRequest,
    VerbResponse,
)
from companion.node import QuadNode
from taskflight_common.httpapi import ApiError
from taskflight_common.yamlio import ConfigError


def status_model(node: QuadNode) -> QueueStatusModel:
    return QueueStatusModel.model_validate(node.qapi_status().to_dict())


def verb(node: QuadNode, fn: Callable[..., None], *args: Any) -> VerbResponse:
    """Run a QAPI verb: 409 if the queue's state forbids it, 400 if it is malformed."""
    try:
        fn(*args)
    except QueueStateError as exc:
        raise ApiError(409, str(exc)) from None
    except QueueError as exc:
        raise ApiError(400, str(exc)) from None
    return VerbResponse(ok=True, status=status_model(node))


def router(node: QuadNode) -> APIRouter:
    api = APIRouter(tags=["queue"])

    @api.get("/commands", response_model=CommandListResponse)
    def commands() -> CommandListResponse:
        st = node.qapi_status()
        entries = node.queue.entries
        return CommandListResponse(
            commands=[CommandEntry(id=e.id, index=i, command=FlightCommandModel.model_validate(
                command_to_dict(e.command))) for i, e in enumerate(entries)],
            current_command_index=st.current_command_index, current_command_id=st.current_command_id,
            generation=st.generation)

    @api.post("/commands", response_model=AddedResponse)
    def add_commands(body: Annotated[CommandsBody, Body(description="one command, or {\"commands\": [...]}")]
                     ) -> AddedResponse:
        if isinstance(body, CommandBatch):
            items = [(c, f"commands[{i}]") for i, c in enumerate(body.commands)]
        else:
            items = [(body, "")]
        try:
            cmds = [c.to_command(prefix) for c, prefix in items]
            ids = node.add_commands(cmds)  # the queue checks them all, then adds them all at once
        except (ConfigError, CommandError, QueueError) as exc:
            raise ApiError(400, f"invalid command: {exc}") from None
        position = {e.id: i for i, e in enumerate(node.queue.entries)}
        return AddedResponse(ids=ids, indices=[position.get(i) for i in ids])

    @api.post("/commands/{command_id}/retarget", response_model=FlightCommandModel)
    def retarget(command_id: Annotated[int, Path(description="the executing command's id")],
                 body: RetargetRequest) -> FlightCommandModel:
        try:
            new = node.retarget(command_id, Retarget(**body.model_dump()))
        except QueueStateError as exc:
            raise ApiError(409, str(exc)) from None
        except (QueueError, CommandError) as exc:
            raise ApiError(400, str(exc)) from None
        return FlightCommandModel.model_validate(command_to_dict(new))

    @api.post("/run", response_model=VerbResponse)
    def run() -> VerbResponse:
        return verb(node, node.run)

    @api.post("/stop", response_model=VerbResponse)
    def stop() -> VerbResponse:
        return verb(node, node.stop)

    @api.post("/reset", response_model=VerbResponse)
    def reset() -> VerbResponse:
        return verb(node, node.reset)

    @api.post("/user_confirm", response_model=VerbResponse)
    def user_confirm() -> VerbResponse:
        return verb(node, node.user_confirm)

    @api.post("/external/{stream}", response_model=AcceptedResponse)
    def external(stream: Annotated[str, Path(description=f"one of {', '.join(STREAMS)}")],
                 body: ExternalSample) -> AcceptedResponse:
        try:
            accepted = node.push_external(stream, body.values, body.validity_s)
        except ExternalDataError as exc:
            raise ApiError(400, f"malformed sample: {exc}") from None
        return AcceptedResponse(accepted=accepted)

    return api
