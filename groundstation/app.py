"""The ground service's FastAPI application: routers, errors, access.

Laid out like FastAPI's full-stack template: :mod:`groundstation.api` holds one router per resource,
:mod:`groundstation.schemas` the pydantic models, :mod:`groundstation.db` the tables,
:mod:`groundstation.fleet` the live model of the fleet.

Access: every ``/api`` request needs ``Authorization: Bearer <token>`` (401 without a known
one); an observer's token reads and streams only: any other method answers 403, audited. The check is
made before routing and before the body is read. The WebSocket ``/api/ws`` takes the token as the query
parameter ``token`` or in its first message (browsers cannot set its headers).

Errors: every refusal is ``{"error": "..."}`` (400 a bad body naming the field, 401, 403, 404, 409 the
wrong state, 422 rejected with ``reasons``, 502 / 504 a companion unreachable / silent). The bearer check
and the error shape are the companion's control surface's too (:mod:`taskflight_common.httpapi`).

Nothing from the data runs as code: every answer carries a Content-Security-Policy (:data:`CSP`) that lets a
page run only the service's own scripts and styles (no inline script, no inline style, no other host), and
the web UI inserts every text from the service as text (``static/js/text.js``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles

from taskflight_common.httpapi import (
    BearerAuth,
    Scope,
    advertise_bearer,
    error_response,
    install_error_handlers,
)

from .api import commands, events, fleet_verbs, missions, tasks, vehicles, ws
from .schemas import ErrorAnswer
from .service import GroundService
from .tiles import TileSource

log = logging.getLogger(__name__)

READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
#: the pages' Content-Security-Policy: the service's own scripts, styles, images and connections only
#: (``'self'`` covers the WebSocket of the same host in CSP 3); data: images for the empty favicon
CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "
       "font-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'")
SECURITY_HEADERS = [(b"content-security-policy", CSP.encode("ascii")),
                    (b"x-content-type-options", b"nosniff"), (b"referrer-policy", b"no-referrer")]
#: the operator's web UI: plain ES modules and a vendored Leaflet, served at ``/``
STATIC = Path(__file__).with_name("static")


class Access(BearerAuth):
    """ASGI middleware: bearer token and role on ``/api`` HTTP requests (module docstring)."""

    def __init__(self, app: Any, service: GroundService) -> None:
        super().__init__(app, service.tokens.check, lambda path: path.startswith("/api/"))
        self.service = service

    async def admit(self, scope: Scope, principal: Any) -> JSONResponse | None:
        """403 (audited) for a caller whose role may not command, on anything but a read."""
        method = scope.get("method", "GET")
        if method in READ_METHODS or principal.may_command:
            return None
        path = scope.get("path", "")
        message = f"forbidden: the {principal.role} role may not {method} {path}"
        await asyncio.to_thread(self.service.audit, principal, f"{method} {path}", path, None, 403,
                                {"error": message})
        return error_response(403, message)


class SecurityHeaders:
    """ASGI middleware: ``headers`` (default :data:`SECURITY_HEADERS`) on every HTTP answer (the page, its
    assets, the API)."""

    def __init__(self, app: Any, headers: list[tuple[bytes, bytes]] | None = None) -> None:
        self.app = app
        self.headers = headers if headers is not None else SECURITY_HEADERS

    async def __call__(self, scope: Scope, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def with_headers(message: dict[str, Any]) -> None:
            if message["type"] == "http.response.start":
                names = {k.lower() for k, _ in message.get("headers", [])}
                message["headers"] = list(message.get("headers", [])) + [
                    (k, v) for k, v in self.headers if k not in names]
            await send(message)

        await self.app(scope, receive, with_headers)


def security_headers(tiles: TileSource | None) -> list[tuple[bytes, bytes]]:
    """:data:`SECURITY_HEADERS`, the CSP's ``img-src`` widened to a ``--tiles`` URL template's origin (its
    images only: scripts stay the service's own)."""
    origin = tiles.origin() if tiles is not None else None
    if origin is None:
        return SECURITY_HEADERS
    csp = CSP.replace("img-src 'self' data:", f"img-src 'self' data: {origin}")
    return [(b"content-security-policy", csp.encode("ascii")), *SECURITY_HEADERS[1:]]


def create_app(service: GroundService, snapshot_period_s: float = 0.1,
               tiles: TileSource | None = None) -> FastAPI:
    """The application serving ``service`` (started and closed with the application's lifespan);
    ``tiles``: the map's raster tiles (:mod:`groundstation.tiles`; without them the map draws a grid)."""

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
    app.add_middleware(SecurityHeaders, headers=security_headers(tiles))

    advertise_bearer(app)
    install_error_handlers(app)

    @app.exception_handler(Exception)
    async def _crash(request: Request, exc: Exception) -> JSONResponse:
        log.exception("ground service: %s %s failed", request.method, request.url.path)
        return error_response(500, f"internal error: {type(exc).__name__}")

    for module in (vehicles, tasks, commands, events, fleet_verbs, missions):
        app.include_router(module.router, prefix="/api")
    app.include_router(ws.router, prefix="/api")
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/api/map", tags=["map"])
    def map_config() -> dict[str, Any]:
        """The map's base layer: ``{"tiles": {url, minzoom, maxzoom, bounds, attribution}}`` or
        ``{"tiles": null}`` (the page then draws a scale grid)."""
        return {"tiles": tiles.info() if tiles is not None else None}

    @app.get("/tiles/{z}/{x}/{y}.png", include_in_schema=False)
    def tile(z: int, x: int, y: int) -> Response:
        """A raster tile of the ``--tiles`` MBTiles file (no token: an <img> sends none; 404 where the file
        has no tile)."""
        data = tiles.mbtiles.tile(z, x, y) if tiles is not None and tiles.mbtiles is not None else None
        if data is None:
            return Response(status_code=404)
        return Response(data, media_type=tiles.mbtiles.mime if tiles and tiles.mbtiles else "image/png",
                        headers={"Cache-Control": "max-age=3600"})

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        """The operator's web UI; every asset is served from ``/static``."""
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-cache"})

    return app
