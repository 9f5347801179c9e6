"""The ground service's core: the team-control station, the fleet, the database, the events.

Seed 003 Fig. 1: the operator commands the team by task through the Team Control interface (the
station of :mod:`companion.team.station`, the one writer of the task board) and single vehicles through
the Process Monitor (:mod:`groundstation.companions`). :class:`GroundService` joins the team link as the
station, persists every task change, assignment, mission, registration, command and event in the
database (:mod:`groundstation.db`) and, started again on the same database, restores the station's ledger
with the same ids and states and publishes it with a newer (stamp, seq): the vehicles keep their tasks
(the team needs no station to go on, seed 003 Sec. III-B).
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import yaml
from shapely.geometry import Polygon

from companion.team.auth import warn_if_unauthenticated
from companion.team.station import TeamControlStation
from companion.team.tasks import Fence, TaskDef
from companion.team.transport import Transport, open_transport
from taskflight_common.geo import check_point

from .auth import Principal, Tokens
from .companions import VERBS, ApiError, CompanionClient
from .db import Database
from .fleet import Fleet

log = logging.getLogger(__name__)

#: station log entries that change the task list (the ledger is saved after each)
_LEDGER_EVENTS = frozenset({"added", "cancelled", "task", "redivided", "restored"})


class EventHub:
    """Fans events out to the WebSocket clients' queues (any thread may publish)."""

    def __init__(self) -> None:
        self._subs: dict[asyncio.Queue[dict[str, Any]], asyncio.AbstractEventLoop] = {}
        self._lock = threading.Lock()

    def subscribe(self) -> asyncio.Queue[dict[str, Any]]:
        q: asyncio.Queue[dict[str, Any]] = asyncio.Queue(maxsize=1000)
        with self._lock:
            self._subs[q] = asyncio.get_running_loop()
        return q

    def unsubscribe(self, q: asyncio.Queue[dict[str, Any]]) -> None:
        with self._lock:
            self._subs.pop(q, None)

    def publish(self, event: dict[str, Any]) -> None:
        with self._lock:
            subs = list(self._subs.items())
        for q, loop in subs:
            try:
                loop.call_soon_threadsafe(_offer, q, event)
            except RuntimeError:  # the loop is closed
                self.unsubscribe(q)


def _offer(q: asyncio.Queue[dict[str, Any]], event: dict[str, Any]) -> None:
    if not q.full():
        q.put_nowait(event)


def fence_of(points: list[list[float]]) -> Fence:
    """The station's fence from [lat, lon] vertices (ValueError for fewer than 3 or a polygon that is not
    simple)."""
    if len(points) < 3:
        raise ValueError(f"fence: needs at least 3 [lat, lon] vertices, got {len(points)}")
    for i, p in enumerate(points):
        check_point(list(p), f"fence[{i}]")
    poly = Polygon([(float(p[0]), float(p[1])) for p in points])
    if not poly.is_valid or poly.area <= 0:
        raise ValueError("fence: not a simple polygon")
    return Fence(poly)


def load_fence(path: str) -> list[list[float]]:
    """``fence: [[lat, lon], ...]`` from a YAML file (a team task file or a file of its own)."""
    data = yaml.safe_load(Path(path).read_text())
    points = data.get("fence") if isinstance(data, dict) else None
    if not isinstance(points, list):
        raise ValueError(f"{path}: expected 'fence: [[lat, lon], ...]'")
    fence_of(points)
    return [list(map(float, p[:2])) for p in points]


class GroundService:
    """See module docstring. ``companions``: vehicle id -> control URL (also stored in the registry)."""

    def __init__(self, db_path: str, tokens: Tokens, *, team_url: str | None = None,
                 transport: Transport | None = None, companions: dict[int, str] | None = None,
                 companion_token: str | None = None, station_period_s: float | None = None,
                 poll_period_s: float = 0.5, fence: list[list[float]] | None = None,
                 team_key: bytes | None = None) -> None:
        self.db = Database(db_path)
        self.tokens = tokens
        self.hub = EventHub()
        self.client = CompanionClient(companion_token)
        if transport is None:
            transport = open_transport(team_url or "udp://239.255.70.1:14600", member=0,
                                       position_of=lambda m: None)
        self.fence_points = [list(p[:2]) for p in fence] if fence else None
        warn_if_unauthenticated(transport.url, team_key, "ground service")
        self.station = TeamControlStation(transport, period_s=station_period_s, name="ground",
                                          fence=fence_of(fence) if fence else None, key=team_key)
        self.station.listeners.append(self._on_station)
        self.fleet = Fleet(self.station, self.client, self.emit, poll_period_s=poll_period_s)
        for v in self.db.vehicles():
            self.fleet.register(v["id"], v["name"], v["control_url"])
        for vid, url in (companions or {}).items():
            self.register(vid, "", url)
        snap = self.db.ledger()
        if snap is not None:
            self.station.restore(snap)
        self.started = time.time()

    def start(self) -> GroundService:
        self.station.start()
        self.fleet.start()
        return self

    def close(self) -> None:
        self.fleet.close()
        self.station.close()
        self.client.close()
        self.db.close()

    # --- events -------------------------------------------------------------------------------------------
    def emit(self, kind: str, message: str, *, severity: str = "info", vehicle: int | None = None,
             task: int | None = None, data: dict[str, Any] | None = None) -> None:
        t = time.time()
        eid = self.db.add_event(kind, message, severity=severity, vehicle=vehicle, task=task, data=data, t=t)
        self.hub.publish({"type": "event", "id": eid, "t": t, "kind": kind, "severity": severity,
                          "vehicle": vehicle, "task": task, "message": message, "data": data or {}})

    def _on_station(self, entry: dict[str, Any]) -> None:
        """The station's log: task changes are persisted and become events."""
        ev = entry.get("event")
        if ev in _LEDGER_EVENTS:
            self.save_ledger()
        t = entry.get("t")
        if ev == "added":
            for tid in entry["ids"]:
                self.db.add_assignment(tid, "unassigned", None, t)
            self.emit("task_added", f"{entry['kind']} added: tasks {entry['ids']}", data=entry)
        elif ev == "cancelled":
            for tid in entry["ids"]:
                self.db.add_assignment(tid, "cancelled", None, t)
            self.emit("task_cancelled", f"tasks {entry['ids']} cancelled", data=entry)
        elif ev == "task":
            self.db.add_assignment(entry["task"], entry["state"], entry["holder"], t)
            who = f" by vehicle {entry['holder']}" if entry["holder"] is not None else ""
            self.emit("task_state", f"task {entry['task']} {entry['state']}{who}", task=entry["task"],
                      vehicle=entry["holder"], data=entry)
        elif ev in ("conflict", "resolved"):
            self.emit(ev, f"task {entry['task']}: {ev} {entry.get('members', entry.get('holder'))}",
                      severity="warning" if ev == "conflict" else "info", task=entry["task"], data=entry)
        elif ev == "gone":
            self.emit("link_lost", f"vehicle {entry['member']} gone from the team link", severity="warning",
                      vehicle=entry["member"], data=entry)
        elif ev == "joined":
            self.emit("vehicle_joined", f"vehicle {entry['member']} joined the team", vehicle=entry["member"],
                      data=entry)
        elif ev in ("duplicate", "refused"):
            self.emit("duplicate_id", entry["message"], severity="warning", vehicle=entry.get("member"),
                      data=entry)
        elif ev == "restored":
            self.emit("restored", f"task list restored: {entry['tasks']} tasks", data=entry)

    def save_ledger(self) -> None:
        costs = {v.id: v.cost for v in self.station.tasks()}
        self.db.save_ledger(self.station.ledger.export(), costs)

    # --- audit ----------------------------------------------------------------------------------------
    def audit(self, who: Principal, action: str, target: str, body: Any, status: int, answer: Any) -> None:
        self.db.audit(who.name, who.role, action, target, body, status, answer)

    # --- team tasks -----------------------------------------------------------------------------------
    def add_task(self, req: Any) -> dict[str, Any]:
        """Seed 003 Sec. II: a border/area asking for more vehicles than are free -> 409 with the offer."""
        points: tuple[Any, ...] = ()
        if req.type == "visit":
            points = (tuple(req.point),)
        elif req.type in ("patrol_line", "border_patrol"):
            points = tuple(tuple(p) for p in req.points)
        elif req.type == "area_scan":
            points = tuple(tuple(p) for p in req.area)
        defn = TaskDef(req.type, points, n=req.vehicles, altitude=req.altitude, speed=req.speed,
                       name=req.name, tree=req.tree)
        try:
            result = self.station.add(defn, force=req.force)
            if result.offer is not None and req.accept_smaller:
                defn = replace(defn, n=result.offer)
                result = self.station.add(defn, force=True)
        except ValueError as exc:
            raise ApiError(400, str(exc)) from None
        if result.offer is not None:
            raise ApiError(409, f"{req.vehicles} vehicles asked for, {result.free} free: accept "
                                f"{result.offer} "
                                f"(ask again with \"vehicles\": {result.offer} or \"accept_smaller\": true) "
                                "or keep N with \"force\": true", offer=result.offer, free=result.free)
        views = {v.id: v for v in self.station.tasks()}
        group = views[result.ids[0]].group
        return {"ids": list(result.ids), "group": group, "vehicles": defn.n, "free": result.free,
                "tasks": [task_out(views[i]) for i in result.ids]}

    def cancel_task(self, tid: int) -> list[int]:
        try:
            return list(self.station.cancel(tid))
        except ValueError as exc:
            known = tid in self.station.ledger.ids() or bool(self.station.ledger.group_of(tid))
            raise ApiError(409 if known else 404, str(exc)) from None

    def tasks(self) -> list[dict[str, Any]]:
        return [task_out(v) for v in self.station.tasks()]

    # --- vehicles -------------------------------------------------------------------------------------
    def register(self, vid: int, name: str, control_url: str | None) -> None:
        self.db.put_vehicle(vid, name, control_url)
        self.fleet.register(vid, name, control_url)

    def call(self, vid: int, method: str, path: str, body: Any = None) -> tuple[int, Any]:
        return self.client.call(vid, self.fleet.url_of(vid), method, path, body)

    def command(self, vid: int, verb: str, body: Any = None) -> dict[str, Any]:
        """One operator verb to one vehicle -> a CommandAnswer record (ApiError for 404/409/502/504)."""
        method, path, default = VERBS[verb]
        status, answer = self.call(vid, method, path, body if body is not None else default)
        ok = 200 <= status < 300
        if ok and verb == "land" and isinstance(answer, dict) and answer.get("accepted") is False:
            ok, status = False, 409
        error = None if ok else (answer.get("error") or answer.get("reason")) if isinstance(answer, dict) \
            else str(answer)
        return {"vehicle": vid, "command": verb, "ok": ok, "status": status, "answer": answer, "error": error}

    def give_mission(self, vid: int, req: Any) -> dict[str, Any]:
        body = {"mission": req.mission, "tree": req.tree}
        if req.description:
            body["description"] = req.description
        status, answer = self.call(vid, "POST", "/mission", body)
        self.db.add_mission(vid, body, status, answer)
        if status == 422:
            raise ApiError(422, answer.get("error", "rejected"), reasons=answer.get("reasons"))
        if status >= 400:
            raise ApiError(status if status in (400, 404, 409, 415) else 409,
                           f"vehicle {vid}: {answer.get('error') if isinstance(answer, dict) else answer}")
        out = {"vehicle": vid, "command": "mission", "ok": True, "status": status, "answer": answer,
               "error": None}
        if req.start:
            started = self.command(vid, "start", {"break_in": req.break_in})
            if not started["ok"]:
                raise ApiError(409, f"vehicle {vid}: accepted but not started: {started['error']}")
            out["answer"] = {"accepted": answer, "started": started["answer"]}
        return out


def task_out(v: Any) -> dict[str, Any]:
    cost = v.cost if v.cost is not None and math.isfinite(v.cost) else None
    return {"id": v.id, "group": v.group, "kind": v.kind, "state": v.state, "holder": v.holder, "cost": cost,
            "version": v.version, "name": v.name, "points": [list(p) for p in v.points]}
