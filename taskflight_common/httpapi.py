"""What the two HTTP surfaces share: the companion's control surface and the ground service.

* one error shape: every refusal answers ``{"error": "<what and why>"}`` (plus extra fields a refusal
  names, e.g. ``reasons``) with its status code; :class:`ApiError` raised anywhere in a route becomes
  that answer, and :func:`install_error_handlers` turns FastAPI's own refusals (malformed JSON, a body
  of the wrong shape, an unknown path, a method not offered) into it, naming the offending field;
* one bearer-token check: :class:`BearerAuth`, an ASGI middleware that reads
  ``Authorization: Bearer <token>`` before routing and before the body is read (an unauthenticated
  request learns nothing, not even whether its path or body would be valid), and answers 401 with
  ``WWW-Authenticate: Bearer``; :func:`advertise_bearer` declares the scheme in the OpenAPI document.
"""

from __future__ import annotations

import hmac
import json
from collections.abc import Awaitable, Callable, Iterable, MutableMapping
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

#: what a 401 asks for
AUTH_REQUIRED = "authentication required: send 'Authorization: Bearer <token>'"
WRONG_SCHEME = "authentication required: expected the Bearer scheme"
INVALID_TOKEN = "invalid token"
CHALLENGE = {"WWW-Authenticate": 'Bearer realm="taskflight"'}


class ErrorResponse(BaseModel):
    """Every refused request (any 4xx); nothing changed."""

    error: str = Field(examples=["commands[1].end: expected a mapping"])


class ApiError(Exception):
    """A refusal: HTTP status, message and extra fields of the error answer (None-valued ones left out)."""

    def __init__(self, status: int, message: str, **extra: Any) -> None:
        super().__init__(message)
        self.status = status
        self.message = message
        self.extra = {k: v for k, v in extra.items() if v is not None}

    def body(self) -> dict[str, Any]:
        return {"error": self.message, **self.extra}


def error_response(status: int, message: str, headers: dict[str, str] | None = None) -> JSONResponse:
    """The one error shape."""
    return JSONResponse({"error": message}, status_code=status, headers=headers)


# --- FastAPI's own refusals in the one shape ---------------------------------------------------------------
def _where(loc: Any, skip: frozenset[str]) -> str:
    """``commands[1].end`` from pydantic's ``("body", "batch", "commands", 1, "end")``."""
    parts = list(loc) if isinstance(loc, list | tuple) else [loc]
    source = parts.pop(0) if parts and parts[0] in ("body", "query", "path", "header", "cookie") else "body"
    text = ""
    for p in parts:
        if isinstance(p, int):
            text += f"[{p}]"
        elif p in skip or (isinstance(p, str) and (p.startswith("function-") or p.startswith("list["))):
            continue  # a union's tag or a validator's name: not a field the caller wrote
        else:
            text += f".{p}" if text else str(p)
    if source == "body":
        return text or "body"
    return f"{source} parameter {text}"


def validation_message(exc: RequestValidationError, skip: Iterable[str] = ()) -> str:
    """One line naming each offending field (``skip``: union tags left out of the field paths)."""
    tags = frozenset(skip)
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
        where = _where(e.get("loc", ()), tags)
        msg = str(e.get("msg", "invalid")).removeprefix("Value error, ")
        if e.get("type") == "missing" and where == "body":
            msg = "expected a JSON body"
        out.append(f"{where}: {msg}")
    return "; ".join(out) or "invalid request"


def http_message(request: Request, exc: StarletteHTTPException) -> str:
    detail = exc.detail
    if exc.status_code == 404 and detail == "Not Found":
        return f"not found: no endpoint {request.url.path}"
    if exc.status_code == 405 and detail == "Method Not Allowed":
        allowed = (exc.headers or {}).get("Allow") or (exc.headers or {}).get("allow")
        return f"method {request.method} not allowed on {request.url.path}" + (
            f" (allowed: {allowed})" if allowed else "")
    return detail if isinstance(detail, str) else json.dumps(detail)


def install_error_handlers(app: FastAPI, union_tags: Iterable[str] = ()) -> None:
    """:class:`ApiError`, malformed requests and unknown paths or methods answer in the one shape."""
    tags = frozenset(union_tags)

    @app.exception_handler(ApiError)
    async def _refused(request: Request, exc: ApiError) -> JSONResponse:
        return JSONResponse(exc.body(), status_code=exc.status)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return error_response(exc.status_code, http_message(request, exc), dict(exc.headers or {}) or None)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        return error_response(400, validation_message(exc, tags))


# --- the bearer token ---------------------------------------------------------------------------------------
def bearer_token(header: bytes | str | None) -> tuple[str | None, str]:
    """(the token of an ``Authorization`` header, why not if None)."""
    if isinstance(header, bytes):
        header = header.decode("latin-1")
    if not header or not header.strip():
        return None, AUTH_REQUIRED
    scheme, _, credentials = header.strip().partition(" ")
    if scheme.lower() != "bearer":
        return None, WRONG_SCHEME
    token = credentials.strip()
    return (token, "") if token else (None, AUTH_REQUIRED)


def same_token(given: str, expected: str) -> bool:
    """Constant-time comparison."""
    return hmac.compare_digest(given.encode("utf-8"), expected.encode("utf-8"))


class BearerAuth:
    """ASGI middleware: HTTP requests whose path ``guarded(path)`` need a bearer token ``authorize`` knows.

    ``authorize(token)`` returns who holds it (any object) or None (401 ``invalid token``). A subclass
    may refuse an authenticated caller too (:meth:`admit`, e.g. a role that may only read).
    """

    def __init__(self, app: ASGIApp, authorize: Callable[[str], Any | None],
                 guarded: Callable[[str], bool]) -> None:
        self.app = app
        self.authorize = authorize
        self.guarded = guarded

    async def admit(self, scope: Scope, principal: Any) -> JSONResponse | None:
        """None to let ``principal`` through, else the refusal (nothing here: every holder may)."""
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not self.guarded(scope.get("path", "")):
            await self.app(scope, receive, send)
            return
        header = next((v for k, v in scope.get("headers", ()) if k.lower() == b"authorization"), None)
        token, why = bearer_token(header)
        principal = self.authorize(token) if token is not None else None
        if principal is None:
            await error_response(401, why or INVALID_TOKEN, CHALLENGE)(scope, receive, send)
            return
        refused = await self.admit(scope, principal)
        if refused is not None:
            await refused(scope, receive, send)
            return
        scope.setdefault("state", {})["principal"] = principal
        await self.app(scope, receive, send)


def advertise_bearer(app: FastAPI) -> None:
    """Declare the bearer scheme (and that every operation needs it) in ``app``'s OpenAPI document."""
    plain = app.openapi

    def openapi_with_bearer() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = plain()
            schema.setdefault("components", {}).setdefault("securitySchemes", {})["bearer"] = {
                "type": "http", "scheme": "bearer"}
            schema["security"] = [{"bearer": []}]
            app.openapi_schema = schema
        return app.openapi_schema

    app.openapi = openapi_with_bearer  # type: ignore[method-assign]
