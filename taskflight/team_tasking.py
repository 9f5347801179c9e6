"""Giving a running team its tasks from a script (the team demo; seed 003 Sec. II).

Two ways with one interface (:class:`Tasking`): :class:`GroundTasking` through the ground service's REST
API (``POST /api/tasks``, ``GET /api/tasks``, ``DELETE /api/tasks/{id}`` with an operator token), and
:class:`StationTasking`, an in-process team-control station on the team link
(:class:`~companion.team.station.TeamControlStation`) for a fleet started without the ground service.
:func:`http_json` is the small stdlib HTTP client both the demo and ``taskflight up`` use for loopback
JSON calls.
"""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

GeoPoint = tuple[float, float, float]


class HttpError(RuntimeError):
    """A non-2xx answer: ``status`` and the body's text."""

    def __init__(self, status: int, text: str) -> None:
        super().__init__(f"HTTP {status}: {text}")
        self.status = status
        self.text = text


def http_json(method: str, url: str, token: str | None = None, body: Any = None, *,
              content: str | None = None, content_type: str = "application/json",
              timeout_s: float = 10.0) -> Any:
    """One HTTP request with an optional bearer token; the decoded JSON answer (None if empty).
    ``body`` is sent as JSON, ``content`` as text of ``content_type``; HttpError for a non-2xx answer."""
    headers = {"Accept": "application/json"}
    if token:
        headers["Authorization"] = f"Bearer {token}"
    data = None
    if content is not None:
        data, headers["Content-Type"] = content.encode("utf-8"), content_type
    elif body is not None:
        data, headers["Content-Type"] = json.dumps(body).encode("utf-8"), "application/json"
    req = urllib.request.Request(url, data=data, method=method, headers=headers)
    try:
        with urllib.request.urlopen(req, timeout=timeout_s) as r:
            raw = r.read()
    except urllib.error.HTTPError as exc:
        raise HttpError(exc.code, exc.read().decode("utf-8", "replace")) from None
    return json.loads(raw) if raw else None


@dataclass(frozen=True)
class TaskRow:
    """One task as the demo reports it."""

    id: int
    kind: str
    name: str
    state: str
    holder: int | None


class Tasking(Protocol):
    def add(self, kind: str, points: list[GeoPoint], name: str) -> list[int]: ...
    def tasks(self) -> list[TaskRow]: ...
    def cancel(self, task_id: int) -> None: ...
    def close(self) -> None: ...


class StationTasking:
    """An in-process :class:`~companion.team.station.TeamControlStation` on ``team_url``."""

    def __init__(self, team_url: str, key_file: str | None = None) -> None:
        from companion.team.auth import team_key
        from companion.team.station import TeamControlStation
        from companion.team.transport import open_transport

        self.station = TeamControlStation(open_transport(team_url, member=0, position_of=lambda m: None),
                                          key=team_key(key_file))  # else $TASKFLIGHT_TEAM_KEY
        self.station.start()

    def add(self, kind: str, points: list[GeoPoint], name: str) -> list[int]:
        from companion.team.tasks import TaskDef

        result = self.station.add(TaskDef(kind, tuple(points), name=name))
        if result.offer is not None:
            result = self.station.add(TaskDef(kind, tuple(points), n=result.offer, name=name), force=True)
        return list(result.ids)

    def tasks(self) -> list[TaskRow]:
        return [TaskRow(v.id, v.kind, v.name, v.state, v.holder) for v in self.station.tasks()]

    def cancel(self, task_id: int) -> None:
        self.station.cancel(task_id)

    def close(self) -> None:
        self.station.close()


class GroundTasking:
    """The ground service's REST API at ``base_url`` (``http://host:port``) with an operator token."""

    def __init__(self, base_url: str, token: str) -> None:
        self.base = base_url.rstrip("/") + "/api"
        self.token = token

    def add(self, kind: str, points: Sequence[Sequence[float]], name: str) -> list[int]:
        """Each point [lat, lon, alt] or [lat, lon] (the task's default altitude), as ``POST /api/tasks``."""
        body: dict[str, Any] = {"type": kind, "name": name}
        if kind == "visit":
            body["point"] = list(points[0])
        else:
            body["points"] = [list(p) for p in points]
        answer = http_json("POST", self.base + "/tasks", self.token, body)
        ids = answer.get("ids") if isinstance(answer, dict) else None
        if ids is None and isinstance(answer, dict) and "id" in answer:
            ids = [answer["id"]]
        if ids is None and isinstance(answer, dict) and isinstance(answer.get("tasks"), list):
            ids = [t["id"] for t in answer["tasks"]]
        if not ids:
            raise RuntimeError(f"POST /api/tasks: no task added: {answer}")
        return [int(i) for i in ids]

    def tasks(self) -> list[TaskRow]:
        answer = http_json("GET", self.base + "/tasks", self.token)
        rows = answer if isinstance(answer, list) else answer.get("tasks", [])
        out = []
        for t in rows:
            holder = t.get("assignee", t.get("holder"))
            out.append(TaskRow(int(t["id"]), str(t.get("type", t.get("kind", ""))), str(t.get("name", "")),
                               str(t.get("state", "")), None if holder is None else int(holder)))
        return out

    def cancel(self, task_id: int) -> None:
        http_json("DELETE", f"{self.base}/tasks/{task_id}", self.token)

    def close(self) -> None:
        pass
