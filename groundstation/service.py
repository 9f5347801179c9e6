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
import collections
import logging
import math
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import yaml
from shapely.geometry import Polygon

from companion.team.auth import warn_if_unauthenticated
from companion.team.station import TeamControlStation
from companion.team.tasks import Fence, TaskDef
from companion.team.transport import Transport, open_transport
from taskflight_common.geo import check_point

from .alerts import AlertWatch
from .auth import Principal, Tokens
from .companions import VERBS, ApiError, CompanionClient
from .db import Database
from .fleet import Fleet

log = logging.getLogger(__name__)



class Outbox:
    """One WebSocket client's outbound messages: events queued in order (bounded: the oldest dropped and
    counted), snapshots in one slot that the next one replaces, so a slow client is sent the newest
    snapshot, never a backlog of old ones. Used from its event loop's thread only."""

    def __init__(self, max_events: int = 1000) -> None:
        self.events: collections.deque[Any] = collections.deque(maxlen=max_events)
        self.snapshot: Any = None
        self.dropped_events = self.replaced_snapshots = 0
        self._ready = asyncio.Event()

    def put_event(self, item: Any) -> None:
        if len(self.events) == self.events.maxlen:
            self.dropped_events += 1
        self.events.append(item)
        self._ready.set()

    def put_snapshot(self, item: Any) -> None:
        if self.snapshot is not None:
            self.replaced_snapshots += 1
        self.snapshot = item
        self._ready.set()

    async def get(self) -> Any:
        """The next message: the queued events first, then the newest snapshot."""
        while True:
            if self.events:
                return self.events.popleft()
            if self.snapshot is not None:
                item, self.snapshot = self.snapshot, None
                return item
            self._ready.clear()
            await self._ready.wait()


class EventHub:
    """Fans events out to the WebSocket clients' outboxes (any thread may publish)."""

    def __init__(self) -> None:
        self._subs: dict[Outbox, asyncio.AbstractEventLoop] = {}
        self._lock = threading.Lock()

    def subscribe(self) -> Outbox:
        box = Outbox()
        with self._lock:
            self._subs[box] = asyncio.get_running_loop()
        return box

    def unsubscribe(self, box: Outbox) -> None:
        with self._lock:
            self._subs.pop(box, None)

    def publish(self, event: dict[str, Any]) -> None:
        with self._lock:
            subs = list(self._subs.items())
        for box, loop in subs:
            try:
                loop.call_soon_threadsafe(box.put_event, event)
            except RuntimeError:  # the loop is closed
                self.unsubscribe(box)


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
                 team_key: bytes | None = None, resume_tasks: bool = False,
                 retention: Retention | None = None) -> None:
        self.db = Database(db_path)
        self.tokens = tokens
        self.retention = retention or Retention()
        self.hub = EventHub()
        self.alerts = AlertWatch(self.emit)
        self._dirty: set[int] = set()  #: tasks whose last write failed (written again with the next)
        self.client = CompanionClient(companion_token)
        if transport is None:
            transport = open_transport(team_url or "udp://239.255.70.1:14600", member=0,
                                       position_of=lambda m: None)
        self.fence_points = [list(p[:2]) for p in fence] if fence else None
        warn_if_unauthenticated(transport.url, team_key, "ground service")
        self.station = TeamControlStation(transport, period_s=station_period_s, name="ground",
                                          fence=fence_of(fence) if fence else None, key=team_key)
        self.station.listeners.append(self._on_station)
        self.station.persist = self._persist
        self.fleet = Fleet(self.station, self.client, self.emit, poll_period_s=poll_period_s)
        for v in self.db.vehicles():
            self.fleet.register(v["id"], v["name"], v["control_url"])
        for vid, url in (companions or {}).items():
            self.register(vid, "", url)
        snap = self.db.ledger()
        if snap is not None:
            self.station.restore(snap, hold=not resume_tasks)
        self.started = time.time()
        self._stop = threading.Event()
        self._keeper: threading.Thread | None = None

    def start(self) -> GroundService:
        self.station.start()
        self.fleet.start()
        self._keeper = threading.Thread(target=self._keep, name="ground-keeper", daemon=True)
        self._keeper.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._keeper is not None:
            self._keeper.join(timeout=5.0)
        self.fleet.close()
        self.station.close()
        self.client.close()
        self.db.close()

    # --- events -------------------------------------------------------------------------------------------
    def emit(self, kind: str, message: str, *, severity: str = "info", vehicle: int | None = None,
             task: int | None = None, data: dict[str, Any] | None = None) -> None:
        """Store an event and send it to every client (a failed write is logged: the event still goes
        out live, with id 0)."""
        t = time.time()
        try:
            eid = self.db.add_event(kind, message, severity=severity, vehicle=vehicle, task=task, data=data,
                                    t=t)
        except ApiError as exc:
            log.error("event %s not stored: %s", kind, exc.message)
            eid = 0
        self.hub.publish({"type": "event", "id": eid, "t": t, "kind": kind, "severity": severity,
                          "vehicle": vehicle, "task": task, "message": message, "data": data or {},
                          "acked_by": None, "acked_at": None})

    def acknowledge(self, eid: int, who: Principal) -> dict[str, Any]:
        """An operator acknowledges alert ``eid``: stored once (the first acknowledgement stays) and sent
        to every client (``{"type": "ack", ...}``). ApiError 404 for an unknown id."""
        row = self.db.ack_event(eid, who.name)
        if row is None:
            raise ApiError(404, f"no event {eid}")
        self.hub.publish({"type": "ack", "id": eid, "acked_by": row["acked_by"], "acked_at": row["acked_at"]})
        return row

    # --- persistence of the task ledger: one task a change, never the whole ledger ---------------------
    def _task_rows(self, ids: list[int]) -> list[Any]:
        led = self.station.ledger
        return [(led.task(i), led.state(i), led.holder(i), self.station.cost_of(i)) for i in ids]

    def _meta(self) -> dict[str, Any]:
        stamp, seq = self.station.ledger.stamp_seq
        return {"next_id": self.station.ledger.next_id, "seq": seq, "stamp": stamp}

    def _persist(self, entry: dict[str, Any]) -> None:
        """The station's hook for an operator verb (added, cancelled, redivided): its tasks, groups,
        assignment rows and the board's meta in one transaction, before the change is published (a
        failure raises :class:`~.db.StorageError`, 503, and the station undoes the change)."""
        ev, t, ids = entry["event"], entry.get("t"), [int(i) for i in entry.get("ids", [])]
        led = self.station.ledger
        dirty, self._dirty = self._dirty, set()
        if ev == "redivided":  # rare: the old pieces were cancelled as well, so the whole ledger
            snap = led.export()
            rows = [(task, st, h, self.station.cost_of(task.id)) for task, st, h in snap.tasks]
            groups = list(snap.groups)
        else:
            gids = sorted({led.task(i).group for i in ids} - {0})
            groups = [(g, *grp) for g in gids if (grp := led.group(g)) is not None]
            rows = self._task_rows(sorted(set(ids) | dirty))
        state = "cancelled" if ev == "cancelled" else "unassigned"
        try:
            self.db.save_tasks(rows, groups, self._meta(), [(i, state, None, t) for i in ids])
        except BaseException:
            self._dirty |= dirty
            raise

    def _save_changed(self, ids: list[int], assignments: list[tuple[int, str, int | None, float | None]]
                      ) -> None:
        """A task event of the team (or a restore): these tasks and the meta; a failure is logged and the
        tasks written again with the next change."""
        dirty, self._dirty = self._dirty, set()
        try:
            self.db.save_tasks(self._task_rows(sorted(set(ids) | dirty)), (), self._meta(), assignments)
        except ApiError as exc:
            self._dirty |= dirty | set(ids)
            log.error("task change not stored (written again with the next): %s", exc.message)

    def _on_station(self, entry: dict[str, Any]) -> None:
        """The station's log: team task changes are persisted and become events (an operator verb's
        change was persisted before it was published, :meth:`_persist`)."""
        ev = entry.get("event")
        t = entry.get("t")
        if ev == "added":
            self.emit("task_added", f"{entry['kind']} added: tasks {entry['ids']}", data=entry)
        elif ev == "cancelled":
            self.emit("task_cancelled", f"tasks {entry['ids']} cancelled", data=entry)
        elif ev == "task":
            self._save_changed([entry["task"]], [(entry["task"], entry["state"], entry["holder"], t)])
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
            self._save_changed([], [])
            held = entry.get("held") or []
            self.emit("restored", f"task list restored: {entry['tasks']} tasks"
                                  + (f", {len(held)} open ones held until the operator releases them ({held})"
                                     if held else ""), severity="warning" if held else "info", data=entry)
        elif ev == "kept":
            self._save_changed([], [])
            if entry["ids"]:
                self.emit("tasks_kept", f"tasks {entry['ids']} kept: live vehicles fly them", data=entry)
        elif ev == "released":
            self._save_changed([], [])
            self.emit("tasks_released", f"tasks {entry['ids']} released to the team", data=entry)

    def save_ledger(self) -> None:
        """The whole ledger in one transaction (not used on task events)."""
        costs = {v.id: v.cost for v in self.station.tasks()}
        self.db.save_ledger(self.station.ledger.export(), costs)

    def release_tasks(self, ids: list[int] | None) -> list[int]:
        """Give held tasks (all: ``None``) to the team. ApiError 409 naming ids that are not held."""
        try:
            return list(self.station.release(ids))
        except ValueError as exc:
            raise ApiError(409, str(exc)) from None

    # --- telemetry, alerts, retention ---------------------------------------------------------------------
    def _keep(self) -> None:
        """Once a ``telemetry_period_s``: every vehicle's position and status stored (the replay) and looked
        at for alerts; once a ``prune_period_s``: events and telemetry past their keep times deleted."""
        r = self.retention
        next_prune = time.monotonic() + 5.0
        while not self._stop.wait(r.telemetry_period_s):
            try:
                records = self.fleet.snapshot()
                self.alerts.look(records, self.fleet.duplicates())
                self.db.add_telemetry(telemetry_rows(records, time.time()))
                if time.monotonic() >= next_prune:
                    next_prune = time.monotonic() + r.prune_period_s
                    ev, tel = self.db.prune(r.events_keep_s, r.telemetry_keep_s)
                    if ev or tel:
                        log.info("retention: %d events and %d telemetry samples pruned", ev, tel)
            except Exception:
                log.exception("ground keeper: telemetry or retention failed")

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

    def call(self, vid: int, method: str, path: str, body: Any = None,
             timeout_s: float | None = None) -> tuple[int, Any]:
        return self.client.call(vid, self.fleet.url_of(vid), method, path, body, timeout_s)

    def command(self, vid: int, verb: str, body: Any = None) -> dict[str, Any]:
        """One operator verb to one vehicle -> a CommandAnswer record (ApiError for 404/409/502/504)."""
        method, path, default = VERBS[verb]
        status, answer = self.call(vid, method, path, body if body is not None else default)
        ok = 200 <= status < 300
        if ok and verb == "land" and isinstance(answer, dict) and answer.get("accepted") is False:
            ok, status = False, 409
        error = None if ok else (answer.get("error") or answer.get("reason")) if isinstance(answer, dict) \
            else str(answer)
        if ok and verb in ("rtl", "land"):
            self.fleet.commanded(vid, verb)
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


@dataclass(frozen=True)
class Retention:
    """How long events and telemetry are kept (s), how often telemetry is sampled and pruning runs."""

    events_keep_s: float = 30 * 86400.0
    telemetry_keep_s: float = 3600.0
    telemetry_period_s: float = 1.0
    prune_period_s: float = 60.0

    def __post_init__(self) -> None:
        for name in ("events_keep_s", "telemetry_keep_s", "telemetry_period_s", "prune_period_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"retention: {name} must be a positive number of seconds, got {v!r}")


def telemetry_rows(records: list[dict[str, Any]], t: float) -> list[tuple[Any, ...]]:
    """The telemetry table's rows of one look at the fleet (vehicles with a position)."""
    out = []
    for v in records:
        p = v.get("position")
        if not p:
            continue
        armed = v.get("armed")
        out.append((t, v["id"], p["lat"], p["lon"], p["alt"], v.get("heading"), v.get("mode"),
                    None if armed is None else int(bool(armed)), v.get("battery"), v["health"]["level"]))
    return out


def task_out(v: Any) -> dict[str, Any]:
    cost = v.cost if v.cost is not None and math.isfinite(v.cost) else None
    return {"id": v.id, "group": v.group, "kind": v.kind, "state": v.state, "holder": v.holder, "cost": cost,
            "version": v.version, "name": v.name, "points": [list(p) for p in v.points]}
