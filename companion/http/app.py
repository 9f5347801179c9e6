"""The control surface: the QAPI over HTTP (seed 000 Sec. V), one router per resource.

The paper's QuadNode offers the QAPI as ROS service calls; here they are HTTP endpoints (FastAPI,
served by uvicorn) for the ground service and operators' tools. Every body and answer is JSON and
has a pydantic model, so ``GET /openapi.json`` (and ``/docs``) describe every request and answer.
Commands use the flight codec's format (:mod:`companion.flight.codec`); ids are the queue's
process-unique command ids (:mod:`companion.flight.events`).

=========================================  ===========================================================
``GET  /status``                           QAPI status (Sec. V) + flight phase, link, vehicle, node
                                           (:mod:`companion.http.status`)
``GET  /commands``                         the queued commands ``[{id, index, command}]``, the current
                                           index and id, the queue's generation
``POST /commands``                         one command ``{horizontal, vertical, heading, end}``, or
                                           ``{"commands": [...]}``; atomic (all checked first, then all
                                           added, or none) -> ``{"ids": [...], "indices": [...]}``
``POST /commands/{command_id}/retarget``   change the executing command's target in flight (Sec. IV-D)
                                           ``{north, east, altitude, speed, heading}`` (all optional)
                                           -> the command as it now reads
``GET  /events?since=SEQ``                 the queue's events after SEQ -> ``{"events", "last_seq"}``
``GET  /events/wait?command_id=ID``        the first event of ``kinds`` (comma separated; default
                                           ``FINISHED,FAILED,CANCELLED``) for the command, waiting up
                                           to ``timeout_s`` (default 10, at most 60) ->
                                           ``{"event": {...}}``, or ``{"event": null}`` at the deadline
                                           (:mod:`companion.http.events`)
``POST /run``, ``/stop``, ``/reset``,      the verbs -> ``{"ok": true, "status": {...}}``
``/user_confirm``
``POST /pause_direct``,                    pause routines; optional body ``{"routine_id": "hover"}``
``/pause_after_current``
``GET  /pause_routines``                   the pause routines' ids (:mod:`companion.http.pause_routines`)
``POST /external/{stream}``                an external-data sample ``{"values": [...], "validity_s": 0.5}``
                                           (streams: ext_pos, ext_vel, ext_heading, ext_point, rc_vel);
                                           the queue's routes: :mod:`companion.http.queue`
``/behaviors/...``, ``/beliefs``           the executive layer (seed 001), when served: see
                                           :mod:`companion.http.behaviors`
``POST /rtl``, ``GET /safety``             return home and land (the RTL behavior, as the caller's
                                           requester); the safety monitor's watch and decisions
                                           (:mod:`companion.http.safety`)
``/mission``, ``/mission/...``             the mission layer (seed 000 Sec. III, VII), when served:
                                           see :mod:`companion.http.mission`
``/team``, ``/team/...``, ``/processes``,  the process monitor (seed 003 Fig. 1): the team member when
``/params/{name}``                         served (:mod:`companion.http.team`), the processes and
                                           in-flight parameter tuning (:mod:`companion.http.params`)
``POST /fence``                            the autopilot's polygon fence, uploaded and enabled
                                           (:mod:`companion.http.fence`)
=========================================  ===========================================================

Errors
    Every refused request answers ``{"error": "<what and why>"}`` and changes nothing (the shape the
    ground service answers too, :mod:`taskflight_common.httpapi`):

    * 400: malformed JSON, a body or parameter of the wrong shape or type (the message names the
      field, e.g. ``commands[1].end.e_v``), an invalid command, an unknown routine or stream, a
      malformed sample, a retarget that does not fit the command;
    * 401: a missing or wrong bearer token (see below);
    * 404: an unknown path; 405: a method the path does not offer;
    * 409: the verb is not allowed in the queue's state (user_confirm with nothing waiting, retarget
      of a command that is not executing, a pause during a pause);
    * 429: too many ``/events/wait`` requests waiting at once (the verbs keep their threads).

    Bodies must be sent as ``Content-Type: application/json`` (a browser cannot send that to another
    origin without a CORS preflight, which this surface never grants).

Authentication and the chain of command
    The surface binds to ``127.0.0.1`` unless told otherwise (``taskflight companion --control-host``).
    With tokens (``--tokens FILE``: ``{operator: [..], mission: [..], observer: [..]}``; ``--control-token``
    or the environment variable ``TASKFLIGHT_CONTROL_TOKEN`` is one more operator token) every endpoint
    requires ``Authorization: Bearer <token>``; without it, or with another token, the answer is 401.
    ``/openapi.json`` and ``/docs`` stay open. The token's role is the caller's requester
    (:mod:`companion.http.auth`): observers only read (403 for a write), a body may lower its requester,
    never raise it (403), ``emergency`` is no caller's. Without tokens the surface is open, says so at
    start, and serves on loopback only (another host is refused). Prefer the environment variable or the
    file to the command-line option (other users can read a process's arguments).
"""

from __future__ import annotations

import threading

from fastapi import FastAPI

from companion.behaviors.system import ExecutiveLayer
from companion.http import behaviors as behaviors_api
from companion.http import events, fence, mission, params, pause_routines, queue, status, team
from companion.http import safety as safety_api
from companion.http.auth import OPEN_PATHS, ControlTokens, RoleAuth
from companion.http.models import UNION_TAGS
from companion.mission_service import MissionService
from companion.node import QuadNode
from companion.safety import SafetyMonitor
from companion.team.member import TeamMember
from taskflight_common.httpapi import ErrorResponse, advertise_bearer, install_error_handlers

__all__ = ["OPEN_PATHS", "create_app"]


def create_app(node: QuadNode, token: str | None = None, behaviors: ExecutiveLayer | None = None,
               missions: MissionService | None = None, team_member: TeamMember | None = None,
               tokens: ControlTokens | None = None, *, safety: SafetyMonitor | None = None) -> FastAPI:
    """The FastAPI application serving ``node``'s QAPI (see module docstring).

    ``token``: an operator token; ``tokens``: the tokens by role (:class:`ControlTokens`); either one
    makes every endpoint require ``Authorization: Bearer <token>`` (neither: no authentication).
    ``behaviors``: also serve the executive layer (:mod:`companion.http.behaviors`); ``missions``: the
    mission layer (:mod:`companion.http.mission`); ``safety``: the safety monitor (``GET /safety``;
    ``POST /rtl`` is served with the executive layer); ``team_member``: the vehicle's team member (the process
    monitor's routes, :mod:`companion.http.team`). Autopilot parameters are always served.
    ``app.state.closing`` (a :class:`threading.Event`) ends pending ``/events/wait`` requests when set.
    """
    tokens = ControlTokens.of(token, tokens.by_role if tokens is not None else None)
    app = FastAPI(title="Taskflight companion", description=__doc__ or "",
                  responses={"4XX": {"model": ErrorResponse, "description": "refused; nothing changed"}})
    closing = threading.Event()
    app.state.closing = closing
    app.state.tokens = tokens
    if tokens is not None:
        app.add_middleware(RoleAuth, tokens=tokens)
        advertise_bearer(app)
    install_error_handlers(app, UNION_TAGS)

    app.include_router(status.router(node, behaviors))
    app.include_router(queue.router(node, behaviors))
    app.include_router(events.router(node, closing, missions, behaviors))
    app.include_router(pause_routines.router(node, behaviors))
    if behaviors is not None:
        app.include_router(behaviors_api.router(behaviors))
        app.include_router(safety_api.router(behaviors, safety))
    if missions is not None:
        app.include_router(mission.router(missions, team_member))
    if team_member is not None:
        app.include_router(team.router(team_member))
    app.include_router(params.router(node.param_client(),
                                     behaviors.processes if behaviors is not None else None))
    app.include_router(fence.router(node.fence_client()))
    return app
