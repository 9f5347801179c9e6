"""The ground service's FastAPI application (issue 12 items 1, 7): routers, errors, access.

Laid out like FastAPI's full-stack template: :mod:`groundstation.api` holds one router per resource,
:mod:`groundstation.schemas` the pydantic models, :mod:`groundstation.db` the tables,
:mod:`groundstation.fleet` the live model of the fleet.

Access (item 7): every ``/api`` request needs ``Authorization: Bearer <token>`` (401 without a known
one); an observer's token reads and streams only: any other method answers 403, audited. The check is
made before routing and before the body is read. The WebSocket ``/api/ws`` takes the token as the query
parameter ``token`` or in its first message (browsers cannot set its headers).

Errors: every refusal is ``{"error": "..."}`` (400 a bad body naming the field, 401, 403, 404, 409 the
wrong state, 422 rejected with ``reasons``, 502 / 504 a companion unreachable / silent).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator, Awaitable, Callable, MutableMapping
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from .api import commands, events, tasks, vehicles, ws
from .auth import bearer
from .companions import ApiError
from .schemas import ErrorAnswer
from .service import GroundService

log = logging.getLogger(__name__)

Scope = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]
READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
#: the operator's web UI (issue 13): plain ES modules and a vendored Leaflet, served at ``/``
STATIC = Path(__file__).with_name("static")


def _error(status: int, message: str, headers: dict[str, str] | None = None) -> JSONResponse:
    return JSONResponse({"error": message}, status_code=status, headers=headers)


class Access:
    """ASGI middleware: bearer token and role on ``/api`` HTTP requests (module docstring)."""

    def __init__(self, app: Any, service: GroundService) -> None:
        self.app = app
        self.service = service

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        path = scope.get("path", "")
        if scope["type"] != "http" or not path.startswith("/api/"):
            await self.app(scope, receive, send)
            return
        headers = {k.lower(): v for k, v in scope.get("headers", ())}
        token = bearer(headers.get(b"authorization", b"").decode("latin-1"))
        who = self.service.tokens.check(token)
        if who is None:
            why = "authentication required: send 'Authorization: Bearer <token>'" if token is None \
                else "invalid token"
            await _error(401, why, {"WWW-Authenticate": 'Bearer realm="taskflight"'})(scope, receive, send)
            return
        method = scope.get("method", "GET")
        if method not in READ_METHODS and not who.may_command:
            message = f"forbidden: the {who.role} role may not {method} {path}"
            await asyncio.to_thread(self.service.audit, who, f"{method} {path}", path, None, 403,
                                    {"error": message})
            await _error(403, message)(scope, receive, send)
            return
        scope.setdefault("state", {})["principal"] = who
        await self.app(scope, receive, send)


def _where(loc: Any) -> str:
    parts = list(loc) if isinstance(loc, list | tuple) else [loc]
    source = parts.pop(0) if parts and parts[0] in ("body", "query", "path", "header") else "body"
    text = ""
    for p in parts:
        if isinstance(p, int):
            text += f"[{p}]"
        elif not (isinstance(p, str) and (p.startswith("function-") or p.startswith("list["))):
            text += f".{p}" if text else str(p)
    return (text or "body") if source == "body" else f"{source} parameter {text}"


def validation_message(exc: RequestValidationError) -> str:
    out = []
    for e in exc.errors():
        if e.get("type") == "json_invalid":
            return f"malformed JSON: {e.get('ctx', {}).get('error', 'syntax error')}"
        where = _where(e.get("loc", ()))
        msg = str(e.get("msg", "invalid")).removeprefix("Value error, ")
        if e.get("type") == "missing" and where == "body":
            msg = "expected a JSON body"
        out.append(f"{where}: {msg}")
    return "; ".join(out) or "invalid request"


def create_app(service: GroundService, snapshot_period_s: float = 0.1) -> FastAPI:
    """The application serving ``service`` (started and closed with the application's lifespan)."""

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        task = asyncio.create_task(ws.broadcast(app, service, snapshot_period_s))
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
            await service.client.aclose()

    app = FastAPI(title="Taskflight ground service", description=__doc__ or "", lifespan=lifespan,
                  responses={"4XX": {"model": ErrorAnswer, "description": "refused; nothing changed"},
                             "5XX": {"model": ErrorAnswer, "description": "a companion did not answer"}})
    app.state.service = service
    app.state.sockets = set()
    app.add_middleware(Access, service=service)

    base_openapi = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = base_openapi()
            schema.setdefault("components", {}).setdefault("securitySchemes", {})["bearer"] = {
                "type": "http", "scheme": "bearer"}
            schema["security"] = [{"bearer": []}]
            app.openapi_schema = schema
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]

    @app.exception_handler(ApiError)
    async def _refused(request: Request, exc: ApiError) -> JSONResponse:
        return JSONResponse(exc.body(), status_code=exc.status)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        return _error(400, validation_message(exc))

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        detail = exc.detail
        if exc.status_code == 404 and detail == "Not Found":
            detail = f"not found: no endpoint {request.url.path}"
        elif exc.status_code == 405:
            detail = f"method {request.method} not allowed on {request.url.path}"
        return _error(exc.status_code, detail if isinstance(detail, str) else json.dumps(detail),
                      headers=getattr(exc, "headers", None))

    @app.exception_handler(Exception)
    async def _crash(request: Request, exc: Exception) -> JSONResponse:
        log.exception("ground service: %s %s failed", request.method, request.url.path)
        return _error(500, f"internal error: {type(exc).__name__}")

    for module in (vehicles, tasks, commands, events):
        app.include_router(module.router, prefix="/api")
    app.include_router(ws.router, prefix="/api")
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        """The operator's web UI (issue 13); every asset is served from ``/static``."""
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-cache"})

    return app
