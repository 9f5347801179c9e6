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
                                           (streams: ext_pos, ext_vel, ext_heading, ext_point, rc_vel),
                                           optionally ``age_ms``, ``seq``, ``sender``: stale or out-of-order
                                           samples are dropped -> ``{"accepted": false, "reason"}``
=========================================  ===========================================================

With the executive layer on (seed 001: one writer of the queue, the behavior coordinator)
    * ``POST /commands`` is the FLY_COMMANDS behavior activated by the caller's requester (its token's
      role, :mod:`companion.http.auth`): it replaces the flight behavior (KEEP_HOVERING and any behavior
      of a requester of equal or lower priority), or, when the caller's own FLY_COMMANDS is flying, the
      commands are appended to it. Refused -> 409 ``{"error": reason, ...}``, nothing queued. The answer
      adds ``activation_id``.
    * the verbs (``/run``, ``/stop``, ``/reset``, ``/user_confirm``, the pause routines, retarget, the
      external streams) act on the queue as without it, for a caller whose priority is at least that of
      the requester holding the queue (the operator-assistance pause if one is active, else the active
      flight behavior); otherwise 409 naming the holder. ``/stop`` and the pauses pause the holding
      behavior (its time-out does not run), ``/run`` resumes it, ``/reset`` cancels its commands (it ends
      ``interrupted``; the default behavior then holds the vehicle).

Without it (``--no-behaviors``) the routes drive the queue directly, as the QAPI of seed 000.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any

from fastapi import APIRouter, Body, Path

from companion.behaviors.system import ExecutiveLayer
from companion.flight import (
    STREAMS,
    CommandError,
    ExternalDataError,
    QueueError,
    QueueStateError,
    Retarget,
    command_to_dict,
)
from companion.http.auth import Role
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


def hold_check(layer: ExecutiveLayer | None, role: str, verb_name: str) -> None:
    """409 unless ``role`` may apply ``verb_name`` to the queue now (the executive layer on: its priority at
    least that of the queue's holder); nothing to check without the layer."""
    if layer is None:
        return
    why = layer.coordinator.authority(role, verb_name)
    if why is not None:
        raise ApiError(409, why)


def router(node: QuadNode, layer: ExecutiveLayer | None = None) -> APIRouter:
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

    @api.post("/commands", response_model=AddedResponse, response_model_exclude_none=True)
    def add_commands(body: Annotated[CommandsBody, Body(description="one command, or {\"commands\": [...]}")],
                     role: Role) -> AddedResponse:
        if isinstance(body, CommandBatch):
            items = [(c, f"commands[{i}]") for i, c in enumerate(body.commands)]
        else:
            items = [(body, "")]
        activation_id = None
        try:
            cmds = [c.to_command(prefix) for c, prefix in items]
            if layer is None:
                ids = node.add_commands(cmds)  # the queue checks them all, then adds them all at once
            else:
                result = layer.coordinator.fly_commands(cmds, role)
                if not result.accepted:
                    raise ApiError(409, f"refused: {result.reason}", **result.to_dict())
                activation_id = result.activation_id
                ids = _ids_of(layer, activation_id, len(cmds))
        except (ConfigError, CommandError, QueueError) as exc:
            raise ApiError(400, f"invalid command: {exc}") from None
        position = {e.id: i for i, e in enumerate(node.queue.entries)}
        return AddedResponse(ids=ids, indices=[position.get(i) for i in ids], activation_id=activation_id)

    @api.post("/commands/{command_id}/retarget", response_model=FlightCommandModel)
    def retarget(command_id: Annotated[int, Path(description="the executing command's id")],
                 body: RetargetRequest, role: Role) -> FlightCommandModel:
        hold_check(layer, role, "retarget")
        try:
            new = node.retarget(command_id, Retarget(**body.model_dump()))
        except QueueStateError as exc:
            raise ApiError(409, str(exc)) from None
        except (QueueError, CommandError) as exc:
            raise ApiError(400, str(exc)) from None
        return FlightCommandModel.model_validate(command_to_dict(new))

    @api.post("/run", response_model=VerbResponse)
    def run(role: Role) -> VerbResponse:
        hold_check(layer, role, "run")
        return verb(node, node.run)

    @api.post("/stop", response_model=VerbResponse)
    def stop(role: Role) -> VerbResponse:
        hold_check(layer, role, "stop")
        return verb(node, node.stop)

    @api.post("/reset", response_model=VerbResponse)
    def reset(role: Role) -> VerbResponse:
        hold_check(layer, role, "reset")
        return verb(node, node.reset)

    @api.post("/user_confirm", response_model=VerbResponse)
    def user_confirm(role: Role) -> VerbResponse:
        hold_check(layer, role, "user_confirm")
        return verb(node, node.user_confirm)

    @api.post("/external/{stream}", response_model=AcceptedResponse)
    def external(stream: Annotated[str, Path(description=f"one of {', '.join(STREAMS)}")],
                 body: ExternalSample, role: Role) -> AcceptedResponse:
        hold_check(layer, role, f"external/{stream}")
        try:
            reason = node.offer_external(stream, body.values, body.validity_s, age_s=body.age_ms / 1000.0,
                                         seq=body.seq, sender=body.sender)
        except ExternalDataError as exc:
            raise ApiError(400, f"malformed sample: {exc}") from None
        return AcceptedResponse(accepted=reason is None, reason=reason)

    return api


def _ids_of(layer: ExecutiveLayer, activation_id: str | None, count: int) -> list[int]:
    """The queue ids of the last ``count`` commands of FLY_COMMANDS (just activated or extended)."""
    act = layer.coordinator.activation("FLY_COMMANDS")
    if act is None or act.activation_id != activation_id:
        return []
    ids = act.controller.status().get("command_ids", [])
    return [int(i) for i in ids[-count:]]
