"""Directed commands to one vehicle's companion (seed 003 Fig. 1: the Process Monitor tier).

Seed 003 Sec. II: the Process Monitor "allows the user to send high-level commands to individual
processes ... If the Team Control interface fails or enters an unsafe command, it can be overridden by
sending task commands to individual aircraft through the Process Monitor." Each vehicle's companion
serves an HTTP control surface (:mod:`companion.http`); :class:`CompanionClient` calls it with the
service's bearer token and turns what can go wrong into :class:`ApiError` s: no such vehicle 404, no
control URL 409, the companion unreachable 502, no answer in time 504, its own refusals passed on.
"""

from __future__ import annotations

import logging
from typing import Any

import httpx

from taskflight_common.httpapi import ApiError

log = logging.getLogger(__name__)

__all__ = ["VERBS", "ApiError", "CompanionClient"]

#: the operator's verbs -> (method, companion path, default body)
VERBS: dict[str, tuple[str, str, Any]] = {
    "start": ("POST", "/mission/start", None),
    "take": ("POST", "/team/take", {"reason": "operator"}),
    "release": ("POST", "/team/release", None),
    "pause": ("POST", "/mission/pause", {"routine_id": "joystick"}),
    "resume": ("POST", "/mission/continue", None),
    "enough": ("POST", "/mission/enough", None),
    "user_confirm": ("POST", "/user_confirm", None),
    "abort": ("POST", "/mission/abort", None),
    "land": ("POST", "/behaviors/activate", {"text": "LAND", "requester": "operator"}),
    "rtl": ("POST", "/rtl", {"requester": "operator"}),
}


class CompanionClient:
    """Calls companions' control surfaces (``token``: their bearer token, or None)."""

    def __init__(self, token: str | None = None, timeout_s: float = 5.0) -> None:
        self.token = token
        self.timeout_s = timeout_s
        self._client = httpx.Client(timeout=timeout_s, headers=self.headers())
        self._async: httpx.AsyncClient | None = None

    def headers(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.token}"} if self.token else {}

    def close(self) -> None:
        self._client.close()

    def call(self, vid: int, url: str | None, method: str, path: str, body: Any = None,
             timeout_s: float | None = None) -> tuple[int, Any]:
        """(status, JSON answer) of the companion; raises ApiError for what is not the companion's own
        answer. A companion's 4xx comes back as (status, answer): the caller decides."""
        if not url:
            raise ApiError(409, f"vehicle {vid} has no control URL: register it with PUT /api/vehicles/{vid}")
        try:
            r = self._client.request(method, url.rstrip("/") + path, json=body,
                                     timeout=timeout_s or self.timeout_s)
        except httpx.TimeoutException:
            raise ApiError(504, f"vehicle {vid}: the companion at {url} did not answer in time") from None
        except httpx.HTTPError as exc:
            raise ApiError(502, f"vehicle {vid}: the companion at {url} is unreachable: {exc}") from None
        try:
            answer = r.json()
        except ValueError:
            answer = {"error": r.text[:200]}
        if r.status_code == 401:
            raise ApiError(502, f"vehicle {vid}: the companion refused the service's token "
                                "(set --companion-token)")
        if r.status_code >= 500:
            raise ApiError(502, f"vehicle {vid}: the companion failed ({r.status_code}): "
                                f"{answer.get('error') if isinstance(answer, dict) else answer}")
        return r.status_code, answer

    async def post_async(self, url: str, path: str, body: Any, timeout_s: float = 1.0) -> int:
        """A fire-and-check POST from the event loop (joystick samples); the status, 0 if unreachable."""
        if self._async is None:
            self._async = httpx.AsyncClient(timeout=timeout_s, headers=self.headers())
        try:
            r = await self._async.post(url.rstrip("/") + path, json=body, timeout=timeout_s)
        except httpx.HTTPError as exc:
            log.debug("joystick to %s failed: %s", url, exc)
            return 0
        return r.status_code

    async def aclose(self) -> None:
        if self._async is not None:
            await self._async.aclose()
            self._async = None
