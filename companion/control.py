"""The control surface: the QAPI over HTTP (issue 4 item 7; seed 000 Sec. V).

The paper's QuadNode offers the QAPI as ROS service calls; here they are HTTP endpoints (FastAPI,
served by uvicorn) for the ground service and operators' tools. Every body and answer is JSON and
has a pydantic model, so ``GET /openapi.json`` (and ``/docs``) describe every request and answer.
Commands use the flight codec's format (:mod:`companion.flight.codec`); ids are the queue's
process-unique command ids (:mod:`companion.flight.events`).

=========================================  ===========================================================
``GET  /status``                           QAPI status (Sec. V) + flight phase, link, vehicle, node
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
``POST /run``, ``/stop``, ``/reset``,      the verbs -> ``{"ok": true, "status": {...}}``
``/user_confirm``
``POST /pause_direct``,                    pause routines; optional body ``{"routine_id": "hover"}``
``/pause_after_current``
``GET  /pause_routines``                       the pause routines' ids
``POST /external/{stream}``                an external-data sample ``{"values": [...], "validity_s": 0.5}``
                                           (streams: ext_pos, ext_vel, ext_heading, ext_point, rc_vel)
``/behaviors/...``, ``/beliefs``           the executive layer (seed 001), when served: see
                                           :mod:`companion.control_behaviors`
``/mission``, ``/mission/...``             the mission layer (seed 000 Sec. III, VII), when served:
                                           see :mod:`companion.control_mission`
``/team``, ``/team/...``, ``/processes``,  the process monitor (seed 003 Fig. 1): the team member when
``/params/{name}``                         served, the processes, in-flight parameter tuning: see
                                           :mod:`companion.control_team`
=========================================  ===========================================================

Errors
    Every refused request answers ``{"error": "<what and why>"}`` and changes nothing:

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

Authentication
    The surface binds to ``127.0.0.1`` unless told otherwise (``taskflight companion --control-host``).
    With a token (``create_app(node, token=...)``, ``ControlServer(..., token=...)``,
    ``--control-token`` or the environment variable ``TASKFLIGHT_CONTROL_TOKEN``) every endpoint
    requires ``Authorization: Bearer <token>``; without it, or with another token, the answer is 401.
    ``/openapi.json`` and ``/docs`` stay open. Serving on a non-loopback address without a token logs
    a warning: anyone who reaches the port can then fly the vehicle. Prefer the environment variable
    to the command-line option (other users can read a process's arguments).
"""

from __future__ import annotations

import hmac
import ipaddress
import json
import logging
import threading
import time
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Annotated, Any

import uvicorn
from fastapi import Body, FastAPI, Path, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from companion.behaviors.system import ExecutiveLayer
from companion.control_behaviors import add_behavior_routes
from companion.control_mission import add_mission_routes
from companion.control_models import (
    UNION_TAGS,
    AcceptedResponse,
    AddedResponse,
    CommandBatch,
    CommandEntry,
    CommandListResponse,
    CommandsBody,
    ErrorResponse,
    EventModel,
    EventsResponse,
    EventWaitResponse,
    ExternalSample,
    FlightCommandModel,
    PauseRequest,
    PauseRoutinesResponse,
    QueueStatusModel,
    RetargetRequest,
    StatusResponse,
    VerbResponse,
)
from companion.control_team import add_param_routes, add_team_routes
from companion.flight import (
    STREAMS,
    CommandError,
    EventKind,
    ExternalDataError,
    QueueError,
    QueueEvent,
    QueueStateError,
    Retarget,
    command_to_dict,
)
from companion.flight.events import TERMINAL
from companion.link.params import ParamClient
from companion.mission_service import MissionService
from companion.node import QuadNode
from companion.team.member import TeamMember
from taskflight_common.yamlio import ConfigError

log = logging.getLogger(__name__)

#: the environment variable ``taskflight companion`` reads the token from
TOKEN_ENV = "TASKFLIGHT_CONTROL_TOKEN"
#: longest wait of ``GET /events/wait`` (s)
MAX_WAIT_S = 60.0
#: how many ``GET /events/wait`` may block a worker thread at once (the default pool has 40)
MAX_WAITERS = 16
#: paths served without a token
OPEN_PATHS = frozenset({"/openapi.json", "/docs", "/docs/oauth2-redirect", "/redoc"})

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

#: a JSON number (an integer is accepted; booleans and strings are not), finite
# --- errors ----------------------------------------------------------------------------------------
class RequestError(Exception):
    """A request the surface refuses (status code and message)."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


def _error(status: int, message: str, headers: dict[str, str] | None = None) -> JSONResponse:
    return JSONResponse({"error": message}, status_code=status, headers=headers)


def _where(loc: Any) -> str:
    """``commands[1].end`` from pydantic's ``("body", "batch", "commands", 1, "end")``."""
    parts = list(loc) if isinstance(loc, list | tuple) else [loc]
    source = parts.pop(0) if parts and parts[0] in ("body", "query", "path", "header", "cookie") else "body"
    text = ""
    for p in parts:
        if isinstance(p, int):
            text += f"[{p}]"
        elif p not in UNION_TAGS:
            text += f".{p}" if text else str(p)
    if source == "body":
        return text or "body"
    return f"{source} parameter {text}"


def _validation_message(exc: RequestValidationError) -> str:
    errors = list(exc.errors())
    for e in errors:
        if e.get("type") == "json_invalid":
            why = e.get("ctx", {}).get("error", "syntax error")
            return f"malformed JSON: {why} at character {e['loc'][-1]}"
    if isinstance(exc.body, bytes | bytearray):  # a body FastAPI did not read as JSON
        try:
            json.loads(exc.body)
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            return f"malformed JSON: {err}"
        return "expected Content-Type: application/json"
    out = []
    for e in errors:
        where = _where(e.get("loc", ()))
        msg = str(e.get("msg", "invalid"))
        if e.get("type") == "missing" and where == "body":
            msg = "expected a JSON body"
        out.append(f"{where}: {msg}")
    return "; ".join(out)


def _http_message(request: Request, exc: StarletteHTTPException) -> str:
    detail = exc.detail
    if exc.status_code == 404 and detail == "Not Found":
        return f"not found: no endpoint {request.url.path}"
    if exc.status_code == 405 and detail == "Method Not Allowed":
        allowed = (exc.headers or {}).get("Allow") or (exc.headers or {}).get("allow")
        return f"method {request.method} not allowed on {request.url.path}" + (
            f" (allowed: {allowed})" if allowed else "")
    return detail if isinstance(detail, str) else json.dumps(detail)


# --- authentication --------------------------------------------------------------------------------
class BearerAuth:
    """ASGI middleware: every HTTP request but :data:`OPEN_PATHS` needs ``Authorization: Bearer <token>``.

    Checked before routing and before the body is read, so an unauthenticated request learns nothing
    (not even whether its path or body would be valid).
    """

    def __init__(self, app: ASGIApp, token: str) -> None:
        self.app = app
        self._token = token.encode("utf-8")

    def _check(self, scope: Scope) -> str | None:
        """None if authorised, else why not."""
        values = [v for k, v in scope.get("headers", ()) if k.lower() == b"authorization"]
        if not values:
            return "authentication required: send 'Authorization: Bearer <token>'"
        scheme, _, credentials = values[0].strip().partition(b" ")
        if scheme.lower() != b"bearer":
            return "authentication required: expected the Bearer scheme"
        if not hmac.compare_digest(credentials.strip(), self._token):
            return "invalid token"
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope.get("path") not in OPEN_PATHS:
            why = self._check(scope)
            if why is not None:
                response = _error(401, why, {"WWW-Authenticate": 'Bearer realm="taskflight"'})
                await response(scope, receive, send)
                return
        await self.app(scope, receive, send)


# --- the application -------------------------------------------------------------------------------
def _status_model(node: QuadNode) -> QueueStatusModel:
    return QueueStatusModel.model_validate(node.queue.status().to_dict())


def _event_model(event: QueueEvent) -> EventModel:
    return EventModel.model_validate(event.to_dict())


def _kinds(text: str | None) -> frozenset[EventKind]:
    if text is None or not text.strip():
        return TERMINAL
    out = set()
    for name in text.split(","):
        name = name.strip().upper()
        try:
            out.add(EventKind[name])
        except KeyError:
            known = ", ".join(k.name for k in EventKind)
            raise RequestError(400, f"query parameter kinds: unknown event kind {name!r} "
                                    f"(known: {known})") from None
    return frozenset(out)


def create_app(node: QuadNode, token: str | None = None, behaviors: ExecutiveLayer | None = None,
               missions: MissionService | None = None, team: TeamMember | None = None) -> FastAPI:
    """The FastAPI application serving ``node``'s QAPI (see module docstring).

    ``token``: require ``Authorization: Bearer <token>`` on every endpoint (None: no authentication).
    ``behaviors``: also serve the executive layer (:mod:`companion.control_behaviors`); ``missions``: the
    mission layer (:mod:`companion.control_mission`); ``team``: the vehicle's team member (the process
    monitor's routes, :mod:`companion.control_team`). Autopilot parameters are always served.
    ``app.state.closing`` (a :class:`threading.Event`) ends pending ``/events/wait`` requests when set.
    """
    if token is not None and (not isinstance(token, str) or not token.strip()):
        raise ValueError("the control token must be a non-empty string")
    app = FastAPI(title="Taskflight companion", description=__doc__ or "",
                  responses={"4XX": {"model": ErrorResponse, "description": "refused; nothing changed"}})
    closing = threading.Event()
    waiters = threading.BoundedSemaphore(MAX_WAITERS)
    app.state.closing = closing

    if token is not None:
        app.add_middleware(BearerAuth, token=token)
        plain_openapi = app.openapi

        def openapi_with_bearer() -> dict[str, Any]:
            if app.openapi_schema is None:
                schema = plain_openapi()
                schema.setdefault("components", {}).setdefault("securitySchemes", {})["bearer"] = {
                    "type": "http", "scheme": "bearer"}
                schema["security"] = [{"bearer": []}]
                app.openapi_schema = schema
            return app.openapi_schema

        app.openapi = openapi_with_bearer  # type: ignore[method-assign]

    @app.exception_handler(RequestError)
    async def _refused(request: Request, exc: RequestError) -> JSONResponse:
        return _error(exc.status, exc.message)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return _error(exc.status_code, _http_message(request, exc), dict(exc.headers or {}) or None)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        return _error(400, _validation_message(exc))

    def _verb(fn: Callable[..., None], *args: Any) -> VerbResponse:
        try:
            fn(*args)
        except QueueStateError as exc:
            raise RequestError(409, str(exc)) from None
        except QueueError as exc:
            raise RequestError(400, str(exc)) from None
        return VerbResponse(ok=True, status=_status_model(node))

    @app.get("/status", response_model=StatusResponse)
    def status() -> StatusResponse:
        out = node.status()
        if behaviors is not None:
            out["awaits_operator"] = behaviors.awaits_operator()
        return StatusResponse.model_validate(out)

    @app.get("/commands", response_model=CommandListResponse)
    def commands() -> CommandListResponse:
        st = node.queue.status()
        entries = node.queue.entries
        return CommandListResponse(
            commands=[CommandEntry(id=e.id, index=i, command=FlightCommandModel.model_validate(
                command_to_dict(e.command))) for i, e in enumerate(entries)],
            current_command_index=st.current_command_index, current_command_id=st.current_command_id,
            generation=st.generation)

    @app.post("/commands", response_model=AddedResponse)
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
            raise RequestError(400, f"invalid command: {exc}") from None
        position = {e.id: i for i, e in enumerate(node.queue.entries)}
        return AddedResponse(ids=ids, indices=[position.get(i) for i in ids])

    @app.post("/commands/{command_id}/retarget", response_model=FlightCommandModel)
    def retarget(command_id: Annotated[int, Path(description="the executing command's id")],
                 body: RetargetRequest) -> FlightCommandModel:
        try:
            new = node.retarget(command_id, Retarget(**body.model_dump()))
        except QueueStateError as exc:
            raise RequestError(409, str(exc)) from None
        except (QueueError, CommandError) as exc:
            raise RequestError(400, str(exc)) from None
        return FlightCommandModel.model_validate(command_to_dict(new))

    @app.get("/events", response_model=EventsResponse)
    def events(since: Annotated[int, Query(ge=0, description="the last sequence number seen")] = 0
               ) -> EventsResponse:
        log_ = node.queue.events
        last = log_.last_seq  # read first: every event up to it is in the answer
        found = log_.since(since)
        return EventsResponse(events=[_event_model(e) for e in found],
                              last_seq=max([last] + [e.seq for e in found]))

    @app.get("/events/wait", response_model=EventWaitResponse)
    def wait_event(command_id: Annotated[int, Query(description="the command's id")],
                   kinds: Annotated[str | None, Query(description="comma-separated event kinds (default "
                                                      "FINISHED,FAILED,CANCELLED)")] = None,
                   timeout_s: Annotated[float, Query(ge=0, le=MAX_WAIT_S, description="s")] = 10.0
                   ) -> EventWaitResponse:
        wanted = _kinds(kinds)
        if not waiters.acquire(blocking=False):
            raise RequestError(429, f"too many waiting requests (at most {MAX_WAITERS})")
        try:
            deadline = time.monotonic() + timeout_s
            while True:  # in slices, so that closing the server ends the wait
                left = deadline - time.monotonic()
                event = node.queue.events.wait_for(command_id, wanted, max(0.0, min(left, 0.5)))
                if event is not None or left <= 0.5 or closing.is_set():
                    return EventWaitResponse(event=_event_model(event) if event is not None else None)
        finally:
            waiters.release()

    @app.post("/run", response_model=VerbResponse)
    def run() -> VerbResponse:
        return _verb(node.run)

    @app.post("/stop", response_model=VerbResponse)
    def stop() -> VerbResponse:
        return _verb(node.stop)

    @app.post("/reset", response_model=VerbResponse)
    def reset() -> VerbResponse:
        return _verb(node.reset)

    @app.post("/user_confirm", response_model=VerbResponse)
    def user_confirm() -> VerbResponse:
        return _verb(node.user_confirm)

    @app.post("/pause_direct", response_model=VerbResponse)
    def pause_direct(body: PauseRequest | None = None) -> VerbResponse:
        return _verb(node.pause_direct, body.routine_id if body is not None else None)

    @app.post("/pause_after_current", response_model=VerbResponse)
    def pause_after_current(body: PauseRequest | None = None) -> VerbResponse:
        return _verb(node.pause_after_current, body.routine_id if body is not None else None)

    @app.get("/pause_routines", response_model=PauseRoutinesResponse)
    def pause_routines() -> PauseRoutinesResponse:
        return PauseRoutinesResponse(pause_routines=list(node.queue.catalog.ids()))

    @app.post("/external/{stream}", response_model=AcceptedResponse)
    def external(stream: Annotated[str, Path(description=f"one of {', '.join(STREAMS)}")],
                 body: ExternalSample) -> AcceptedResponse:
        try:
            accepted = node.push_external(stream, body.values, body.validity_s)
        except ExternalDataError as exc:
            raise RequestError(400, f"malformed sample: {exc}") from None
        return AcceptedResponse(accepted=accepted)

    if behaviors is not None:
        add_behavior_routes(app, behaviors, RequestError)
    if missions is not None:
        add_mission_routes(app, missions, RequestError, team)
    if team is not None:
        add_team_routes(app, team, RequestError)
    add_param_routes(app, ParamClient(node.link), RequestError,
                     behaviors.processes if behaviors is not None else None)
    return app


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class ControlServer:
    """uvicorn serving :func:`create_app` on ``host:port`` in a background thread (port 0: any free)."""

    def __init__(self, node: QuadNode, port: int = 8765, host: str = "127.0.0.1",
                 token: str | None = None, behaviors: ExecutiveLayer | None = None,
                 missions: MissionService | None = None, team: TeamMember | None = None) -> None:
        self.app = create_app(node, token, behaviors, missions, team)
        config = uvicorn.Config(self.app, host=host, port=port, log_level="warning", lifespan="off",
                                timeout_graceful_shutdown=2)
        self.server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self.server.run, name="control-http", daemon=True)
        self.host = host
        self.port = port
        self.token_required = token is not None
        if token is None and not is_loopback(host):
            log.warning("control surface on %s without a token: anyone who reaches the port can fly the "
                        "vehicle (set --control-token or %s)", host, TOKEN_ENV)

    def start(self, timeout_s: float = 10.0) -> ControlServer:
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError(f"control server did not start on {self.host}:{self.port}")
            self._thread.join(0.01)
        sock = self.server.servers[0].sockets[0]
        self.port = sock.getsockname()[1]
        log.info("control surface on %s port %d (%s), %s", self.host, self.port, self.url,
                 "bearer token required" if self.token_required else "no authentication")
        return self

    @property
    def url(self) -> str:
        """Where a client on this machine reaches the surface (loopback for a wildcard host)."""
        host = {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}.get(self.host, self.host)
        if ":" in host and not host.startswith("["):
            host = f"[{host}]"
        return f"http://{host}:{self.port}"

    def close(self) -> None:
        self.app.state.closing.set()
        self.server.should_exit = True
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
