"""The local control surface: the QAPI over HTTP on 127.0.0.1 (issue 4 item 7; seed 000 Sec. V).

The paper's QuadNode offers the QAPI as ROS service calls; here they are HTTP endpoints (FastAPI,
served by uvicorn on the loopback interface only) for the ground service and operators' tools. Every
body and answer is JSON. Commands use the flight codec's format (:mod:`companion.flight.codec`).

==============================  ===============================================================
``GET  /status``                QAPI status (Sec. V) + flight phase, link, vehicle, node
``GET  /commands``              the queued commands (codec form) and the current index
``POST /commands``              one command ``{horizontal, vertical, heading, end}``, or
                                ``{"commands": [...]}`` (all validated first; all or none added)
                                -> ``{"indices": [...]}``
``POST /run``                   run()
``POST /stop``                  stop()
``POST /pause_direct``          pause_direct; optional body ``{"behaviour_id": "joystick"}``
``POST /pause_after_current``   pause_after_current; optional body as above
``POST /reset``                 reset()
``POST /user_confirm``          user_confirm()
``GET  /behaviours``            the pause behaviours' ids
``POST /external/{stream}``     an external-data sample ``{"values": [...], "validity_s": 0.5}``
                                (streams: ext_pos, ext_vel, ext_heading, ext_point, rc_vel)
==============================  ===============================================================

Errors: ``{"error": "<what and why>"}`` with 400 (malformed JSON, invalid command, malformed
sample, unknown behaviour) or 409 (the verb is not allowed in the queue's state, e.g. user_confirm
with nothing waiting). A refused request changes nothing.
"""

from __future__ import annotations

import json
import logging
import threading
from typing import Any

import uvicorn
from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from companion.flight import (
    CommandError,
    ExternalDataError,
    QueueError,
    QueueStateError,
    command_from_dict,
    command_to_dict,
)
from companion.node import QuadNode
from taskflight.yamlio import ConfigError

log = logging.getLogger(__name__)


class RequestError(Exception):
    """A request the surface refuses (status code and message)."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


async def _json_body(request: Request, *, optional: bool = False) -> Any:
    raw = await request.body()
    if not raw.strip():
        if optional:
            return None
        raise RequestError(400, "expected a JSON body")
    try:
        return json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise RequestError(400, f"malformed JSON: {exc}") from None


def _behaviour_id(body: Any) -> str | None:
    if body is None:
        return None
    if not isinstance(body, dict) or set(body) - {"behaviour_id"}:
        raise RequestError(400, 'expected {"behaviour_id": "<id>"} or no body')
    bid = body.get("behaviour_id")
    if bid is not None and not isinstance(bid, str):
        raise RequestError(400, "behaviour_id: expected a string")
    return bid


def create_app(node: QuadNode) -> FastAPI:
    """The FastAPI application serving ``node``'s QAPI (see module docstring)."""
    app = FastAPI(title="Taskflight companion", description=__doc__)

    @app.exception_handler(RequestError)
    async def _bad(request: Request, exc: RequestError) -> JSONResponse:
        return JSONResponse({"error": exc.message}, status_code=exc.status)

    def _verb(fn: Any, *args: Any) -> dict[str, Any]:
        try:
            fn(*args)
        except QueueStateError as exc:
            raise RequestError(409, str(exc)) from None
        except QueueError as exc:
            raise RequestError(400, str(exc)) from None
        return {"ok": True, "status": node.queue.status().to_dict()}

    @app.get("/status")
    def status() -> dict[str, Any]:
        return node.status()

    @app.get("/commands")
    def commands() -> dict[str, Any]:
        return {"commands": [command_to_dict(c) for c in node.queue.commands],
                "current_command_index": node.queue.status().current_command_index}

    @app.post("/commands")
    async def add_commands(request: Request) -> dict[str, Any]:
        body = await _json_body(request)
        if isinstance(body, dict) and "commands" in body:
            items = body["commands"]
            if set(body) != {"commands"} or not isinstance(items, list) or not items:
                raise RequestError(400, 'expected {"commands": [<command>, ...]} with at least one command')
            prefixes = [f"commands[{i}]" for i in range(len(items))]
        else:
            items, prefixes = [body], [""]
        try:
            cmds = [command_from_dict(item, file="<request>", prefix=p) for item, p in zip(items, prefixes,
                                                                                         strict=True)]
        except (ConfigError, CommandError) as exc:
            raise RequestError(400, f"invalid command: {exc}") from None
        indices: list[int] = []
        for c in cmds:  # the queue may refuse one (outside the envelope): nothing is added unless all pass
            try:
                node.queue.check_command(c)
            except (QueueError, CommandError) as exc:
                raise RequestError(400, f"invalid command: {exc}") from None
        try:
            indices = [node.add_command(c) for c in cmds]
        except (QueueError, CommandError) as exc:
            raise RequestError(400, f"invalid command: {exc}") from None
        return {"indices": indices}

    @app.post("/run")
    def run() -> dict[str, Any]:
        return _verb(node.run)

    @app.post("/stop")
    def stop() -> dict[str, Any]:
        return _verb(node.stop)

    @app.post("/reset")
    def reset() -> dict[str, Any]:
        return _verb(node.reset)

    @app.post("/user_confirm")
    def user_confirm() -> dict[str, Any]:
        return _verb(node.user_confirm)

    @app.post("/pause_direct")
    async def pause_direct(request: Request) -> dict[str, Any]:
        return _verb(node.pause_direct, _behaviour_id(await _json_body(request, optional=True)))

    @app.post("/pause_after_current")
    async def pause_after_current(request: Request) -> dict[str, Any]:
        return _verb(node.pause_after_current, _behaviour_id(await _json_body(request, optional=True)))

    @app.get("/behaviours")
    def behaviours() -> dict[str, Any]:
        return {"behaviours": node.queue.catalog.ids()}

    @app.post("/external/{stream}")
    async def external(stream: str, request: Request) -> dict[str, Any]:
        body = await _json_body(request)
        if not isinstance(body, dict) or set(body) - {"values", "validity_s"} or "values" not in body:
            raise RequestError(400, 'expected {"values": [numbers], "validity_s": seconds}')
        values = body["values"]
        if not isinstance(values, list):
            raise RequestError(400, f"{stream}: values: expected a list of numbers")
        try:
            accepted = node.push_external(stream, values, body.get("validity_s", 0.5))
        except ExternalDataError as exc:
            raise RequestError(400, f"malformed sample: {exc}") from None
        return {"accepted": accepted}

    return app


class ControlServer:
    """uvicorn serving :func:`create_app` on ``host:port`` in a background thread (port 0: any free)."""

    def __init__(self, node: QuadNode, port: int = 8765, host: str = "127.0.0.1") -> None:
        config = uvicorn.Config(create_app(node), host=host, port=port, log_level="warning", lifespan="off")
        self.server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self.server.run, name="control-http", daemon=True)
        self.host = host
        self.port = port

    def start(self, timeout_s: float = 10.0) -> ControlServer:
        self._thread.start()
        started = threading.Event()
        for _ in range(int(timeout_s / 0.01)):
            if self.server.started:
                started.set()
                break
            if not self._thread.is_alive():
                break
            threading.Event().wait(0.01)
        if not started.is_set():
            raise RuntimeError(f"control server did not start on {self.host}:{self.port}")
        sock = self.server.servers[0].sockets[0]
        self.port = sock.getsockname()[1]
        log.info("control surface on http://%s:%d", self.host, self.port)
        return self

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    def close(self) -> None:
        self.server.should_exit = True
        self._thread.join(timeout=5.0)
