"""Who may do what on the control surface: requesters come from credentials (seed 001 Definition 3).

A caller's *role* is its bearer token's role in the companion's tokens file
(``taskflight companion --tokens FILE``, YAML ``{operator: [..], mission: [..], observer: [..]}``;
``--control-token`` / ``TASKFLIGHT_CONTROL_TOKEN`` is one more operator token):

=============  =====================================================================================
``operator``   everything; activates behaviors as ``operator`` (or lower, if the body asks)
``mission``    activates behaviors and queues commands as ``mission``; not the operator's break-in
               (``/mission/pause``, ``/mission/continue``) nor autopilot parameters
``observer``   reads only: every write answers 403
=============  =====================================================================================

The requester of an activation is its caller's role; a body's ``requester`` may lower it (an operator
asking as ``mission``), never raise it (403 naming both). ``emergency`` is no token's role: only the
companion's own safety monitor requests as emergency, in-process. Without tokens the surface is open
and serves on loopback only (:class:`~companion.http.server.ControlServer` refuses another host);
every caller is then the operator.
"""

from __future__ import annotations

import hmac
from collections.abc import Mapping, Sequence
from typing import Annotated, Any

from fastapi import Depends, Request
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Scope

from taskflight_common.httpapi import ApiError, BearerAuth, error_response
from taskflight_common.tokens import COMPANION_ROLES

#: paths served without a token
OPEN_PATHS = frozenset({"/openapi.json", "/docs", "/docs/oauth2-redirect", "/redoc"})
#: POSTs that change nothing (an observer may call them)
READ_ONLY_POSTS = frozenset({"/behaviors/check"})
#: writes only the operator may make: the break-in of a mission, the autopilot's parameters and fence
OPERATOR_ONLY = ("/mission/pause", "/mission/continue", "/params/", "/fence")
#: the role of every caller of a surface without tokens (on loopback only)
OPEN_ROLE = "operator"
_READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


class ControlTokens:
    """The accepted tokens by role (:data:`~taskflight_common.tokens.COMPANION_ROLES`); :meth:`role_of`
    compares in constant time per token."""

    def __init__(self, by_role: Mapping[str, Sequence[str]]) -> None:
        self.by_role: dict[str, list[str]] = {}
        for role, tokens in by_role.items():
            if role not in COMPANION_ROLES:
                raise ValueError(f"tokens: unknown role {role!r} (roles: {', '.join(COMPANION_ROLES)})")
            if any(not isinstance(t, str) or not t.strip() for t in tokens):
                raise ValueError(f"tokens: {role}: a token must be a non-empty string")
            if tokens:
                self.by_role[role] = [t.strip() for t in tokens]
        if not self.by_role:
            raise ValueError("tokens: no token at all (give at least an operator token)")

    @classmethod
    def of(cls, token: str | None = None, by_role: Mapping[str, Sequence[str]] | None = None
           ) -> ControlTokens | None:
        """``by_role`` plus ``token`` as one more operator token; None when both are empty."""
        merged: dict[str, list[str]] = {r: list(t) for r, t in (by_role or {}).items()}
        if token is not None:
            if not isinstance(token, str) or not token.strip():
                raise ValueError("the control token must be a non-empty string")
            if token.strip() not in merged.get("operator", []):
                merged.setdefault("operator", []).append(token.strip())
        if not any(merged.values()):
            return None
        return cls(merged)

    def role_of(self, token: str | None) -> str | None:
        if not token:
            return None
        given = token.strip().encode("utf-8")
        found: str | None = None
        for role, tokens in self.by_role.items():
            for t in tokens:
                if hmac.compare_digest(given, t.encode("utf-8")):
                    found = role
        return found

    def roles(self) -> list[str]:
        return [r for r in COMPANION_ROLES if r in self.by_role]


class RoleAuth(BearerAuth):
    """Bearer authentication whose principal is the token's role; observers only read (403 for a write),
    a mission token may not make the operator's writes (:data:`OPERATOR_ONLY`)."""

    def __init__(self, app: ASGIApp, tokens: ControlTokens) -> None:
        super().__init__(app, tokens.role_of, lambda path: path not in OPEN_PATHS)

    async def admit(self, scope: Scope, principal: Any) -> JSONResponse | None:
        path, method = scope.get("path", ""), scope.get("method", "GET")
        if method in _READ_METHODS or path in READ_ONLY_POSTS:
            return None
        if principal == "observer":
            return error_response(403, f"an observer token only reads ({method} {path} is a write)")
        if principal != "operator" and path.startswith(OPERATOR_ONLY):
            return error_response(403, f"{method} {path} needs an operator token (this one is {principal})")
        return None


def caller_role(request: Request) -> str:
    """The caller's role (:data:`OPEN_ROLE` on a surface without tokens)."""
    principal = request.scope.get("state", {}).get("principal")
    return str(principal) if principal is not None else OPEN_ROLE


#: a route's parameter: the caller's role
Role = Annotated[str, Depends(caller_role)]


def requester_for(role: str, asked: str | None, priority: Sequence[str]) -> str:
    """The requester an activation is made with: ``asked`` if it does not outrank ``role`` (``priority``:
    the catalog's requesters, highest first); 400 for an unknown requester, 403 for a raise."""
    if asked is None or asked == role:
        return role
    if asked not in priority:
        raise ApiError(400, f"requester: unknown requester {asked!r} (known: {', '.join(priority)})")
    if role not in priority or priority.index(asked) < priority.index(role):
        lower = [r for r in priority if role in priority and priority.index(r) >= priority.index(role)]
        raise ApiError(403, f"requester: a {role} token may request as {', '.join(lower) or role}, "
                            f"not as {asked}")
    return asked
