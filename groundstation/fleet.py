"""The live model of the fleet (seed 003 Sec. II, Fig. 1).

Two sources per vehicle, as in seed 003's interface hierarchy:

* the team link: the station's group state (seed 003 Sec. III-A) gives each vehicle's row: position,
  velocity, team status, the task it flies, its claims, and whether it is gone (voc run out);
* the companion's control surface (the Process Monitor tier): the autopilot's mode, armed state, battery,
  heading, the QAPI queue status and whether it waits for a confirmation, the mission's active node and
  progress (seed 000 Fig. 5). On a Zenoh team (``zenoh:`` URL) each companion publishes it on the fleet
  bus and :mod:`groundstation.bus` takes it (no polling: a vehicle on another host appears with nothing
  but the team URL in common, its control URL with it); on a ``udp://`` team :class:`Fleet` polls the
  registered companions, each in a worker of its own, so an unreachable one (1.5 s time-outs) never
  delays the others.

:meth:`Fleet.snapshot` merges them into one record per vehicle with a health verdict (green / yellow /
red with the reasons). The poller also turns changes into events (link lost, override, failsafe mode,
confirmation required) through ``emit``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlencode

from companion.team.station import TeamControlStation
from companion.team.types import MemberEntry, MemberStatus
from taskflight_common.geo import ned_to_geodetic

from .companions import ApiError, CompanionClient

#: the camera's beliefs are read every this many polls
DETECTION_EVERY = 4
#: object kinds that are the vehicle's own beliefs about itself, not detections
OWN_KINDS = frozenset({"aerial_robot"})
#: the belief query of the companion's camera objects, URL-encoded
DETECTIONS_PATH = "/beliefs?" + urlencode({"query": "object(?x, ?kind), position(?x, ?p)"})

log = logging.getLogger(__name__)

#: no message for this long (s): yellow, then red
STALE_S, LOST_S = 2.0, 5.0
#: battery remaining (%) below which: yellow, red
BATTERY_LOW, BATTERY_CRITICAL = 30.0, 15.0
#: autopilot modes a failsafe (or a ground station) switches to
FAILSAFE_MODES = frozenset({"RTL", "LAND", "BRAKE", "SMART_RTL"})
#: seconds an operator's RTL or land explains the vehicle's switches to those modes (until it disarms)
COMMANDED_S = 600.0

Emit = Callable[..., None]


@dataclass
class Polled:
    """What a companion's control surface said last."""

    status: dict[str, Any] | None = None
    mission: dict[str, Any] | None = None
    ok_at: float = 0.0              #: monotonic time of the last good answer
    error: str | None = None        #: why the last poll failed
    reachable: bool | None = None   #: None: never polled
    detections: dict[str, dict[str, Any]] = field(default_factory=dict)  #: object id -> what was seen
    polls: int = 0
    via_bus: bool = False           #: heard on the fleet bus (not polled)


#: ``mission`` of :meth:`Fleet.heard_on_bus` when a message leaves it out (the last one holds)
KEEP: Any = object()

#: companions polled at once at most (each unreachable one holds a worker for its time-outs)
POLL_WORKERS = 32
#: the polls a second the service makes at most: above ``POLL_RATE_MAX * poll_period_s`` companions the
#: period grows with the fleet (25 vehicles: every 1.25 s; 50: 2.5 s), so that a large fleet on a ``udp://``
#: team is not kept busy answering its ground station (each poll costs the companion a request). Positions
#: do not wait for it (they come with the team rows); a queue's or a mission's state does. A fleet on the
#: Zenoh bus is not polled at all.
POLL_RATE_MAX = 20.0


@dataclass
class Registered:
    name: str = ""
    control_url: str | None = None


@dataclass
class _Seen:
    stamp: float = math.nan
    seq: int = -1
    at: float = 0.0                 #: monotonic time the row last changed


@dataclass
class Fleet:
    """See module docstring. ``emit(kind, message, severity=, vehicle=, task=, data=)`` records events."""

    station: TeamControlStation
    client: CompanionClient
    emit: Emit
    poll_period_s: float = 0.5
    registry: dict[int, Registered] = field(default_factory=dict)
    _polled: dict[int, Polled] = field(default_factory=dict)
    _seen: dict[int, _Seen] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None
    _cache: tuple[float, list[dict[str, Any]]] = (-1.0, [])
    #: HTTP polls of the companions' control surfaces made so far (0 on a Zenoh team)
    http_polls: int = 0
    #: the fleet-bus subscription (a Zenoh team), made by :meth:`start`
    bus: Any = None
    _pool: ThreadPoolExecutor | None = None
    _inflight: set[int] = field(default_factory=set)
    #: vehicle -> (monotonic time, verb) of the operator's last RTL or land through this service
    _commanded: dict[int, tuple[float, str]] = field(default_factory=dict)

    # --- lifecycle -------------------------------------------------------------------------------------
    def start(self) -> Fleet:
        from .bus import FleetBus

        self.bus = FleetBus.for_station(self)
        if self.bus is not None:
            self._thread = threading.Thread(target=self.bus.watch_loop, name="fleet-bus", daemon=True)
        else:
            self._pool = ThreadPoolExecutor(POLL_WORKERS, thread_name_prefix="fleet-poll")
            self._thread = threading.Thread(target=self._poll_loop, name="fleet-poll", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self.bus is not None:
            self.bus.close()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)

    def register(self, vid: int, name: str, control_url: str | None) -> None:
        with self._lock:
            self.registry[vid] = Registered(name, control_url)

    def url_of(self, vid: int) -> str | None:
        """The vehicle's control URL; ApiError 404 for a vehicle neither registered nor heard."""
        with self._lock:
            reg = self.registry.get(vid)
        if reg is None:
            if self.station.state.get(vid) is None or vid == 0:
                raise ApiError(404, f"no vehicle {vid}")
            return None
        return reg.control_url

    def ids(self) -> list[int]:
        with self._lock:
            ids = set(self.registry)
        ids |= {m for m, e in self.station.state.entries().items() if e.status is not MemberStatus.STATION}
        return sorted(ids)

    # --- polling the companions ------------------------------------------------------------------------
    def _poll_loop(self) -> None:
        """Every period, each registered companion whose last poll has ended is polled in a worker of its
        own: a slow or unreachable one holds only its worker."""
        assert self._pool is not None
        while not self._stop.is_set():
            start = time.monotonic()
            with self._lock:
                targets = [(v, r.control_url) for v, r in self.registry.items()
                           if r.control_url and v not in self._inflight]
                self._inflight.update(v for v, _ in targets)
            for vid, url in targets:
                try:
                    self._pool.submit(self._poll_guarded, vid, url)
                except RuntimeError:  # shut down
                    return
            self._stop.wait(max(0.05, self.period_s() - (time.monotonic() - start)))

    def period_s(self) -> float:
        """The poll period: ``poll_period_s``, longer above :data:`POLL_RATE_MAX` polls a second."""
        with self._lock:
            n = sum(1 for r in self.registry.values() if r.control_url)
        return max(self.poll_period_s, n / POLL_RATE_MAX)

    def _poll_guarded(self, vid: int, url: str) -> None:
        try:
            if not self._stop.is_set():
                self._poll_one(vid, url)
        except Exception:
            log.exception("fleet: polling vehicle %d failed", vid)
        finally:
            with self._lock:
                self._inflight.discard(vid)

    def _poll_one(self, vid: int, url: str) -> None:
        with self._lock:
            p = self._polled.setdefault(vid, Polled())
            self.http_polls += 1
        try:
            _s, status = self.client.call(vid, url, "GET", "/status", timeout_s=1.5)
            _m, mission = self.client.call(vid, url, "GET", "/mission", timeout_s=1.5)
        except ApiError as exc:
            if p.reachable is not False:
                self.emit("link_lost", f"vehicle {vid}: companion unreachable ({exc.message})",
                          severity="warning", vehicle=vid)
            with self._lock:
                p.reachable, p.error = False, exc.message
            return
        prev = p.status
        with self._lock:
            if p.reachable is False:
                self.emit("link_restored", f"vehicle {vid}: companion answers again", vehicle=vid)
            p.status = status if isinstance(status, dict) and "queue" in status else None
            p.mission = mission if isinstance(mission, dict) and _m == 200 else None
            p.ok_at, p.error, p.reachable = time.monotonic(), None, True
        self._watch(vid, prev, p.status)
        p.polls += 1
        if p.polls % DETECTION_EVERY == 0:
            self._detections(vid, url, p)

    def _detections(self, vid: int, url: str, p: Polled) -> None:
        """The companion's camera beliefs (seed 000 Sec. VII: ``object(7, person)``, ``position(7, (n, e,
        d))``): an object seen for the first time is a ``detection`` event with its lat/lon."""
        try:
            code, answer = self.client.call(vid, url, "GET", DETECTIONS_PATH, timeout_s=1.5)
        except ApiError:
            return
        if code != 200 or not isinstance(answer, dict):
            return
        for b in answer.get("bindings") or []:
            self.detected(vid, p, b.get("x"), b.get("kind"), b.get("p"))

    def detected(self, vid: int, p: Polled, obj: Any, kind: Any, pos: Any) -> None:
        """An object seen by vehicle ``vid``'s camera: a ``detection`` event with its lat/lon the first
        time (its own beliefs and malformed positions are skipped)."""
        key = str(obj)
        if key in p.detections or kind in OWN_KINDS or not isinstance(pos, list | tuple) or len(pos) != 3:
            return
        home = ((p.status or {}).get("vehicle") or {}).get("home")
        data: dict[str, Any] = {"object": obj, "kind": kind, "ned": list(pos)}
        if isinstance(home, list | tuple) and len(home) == 3:
            lat, lon, alt = ned_to_geodetic(tuple(home), *pos)
            data.update(lat=lat, lon=lon, alt=alt - home[2])
        with self._lock:
            p.detections[key] = data
        self.emit("detection", f"vehicle {vid} sees {data['kind']} {data['object']}", vehicle=vid,
                  data=data)

    # --- the fleet bus ---------------------------------------------------------------------------------
    def polled(self, vid: int) -> Polled:
        with self._lock:
            return self._polled.setdefault(vid, Polled())

    def heard_on_bus(self, vid: int, name: str, control_url: str | None, status: Any, mission: Any) -> None:
        """A vehicle's status message on the fleet bus (:mod:`groundstation.bus`): as a good poll, and the
        control URL it published registered (commands go there)."""
        with self._lock:
            reg = self.registry.get(vid)
            if reg is None or (control_url and reg.control_url != control_url) or (name and not reg.name):
                self.registry[vid] = Registered(name or (reg.name if reg else ""),
                                                control_url or (reg.control_url if reg else None))
            p = self._polled.setdefault(vid, Polled())
            prev, was = p.status, p.reachable
            p.status = status if isinstance(status, dict) and "queue" in status else None
            if mission is not KEEP:
                p.mission = mission if isinstance(mission, dict) else None
            p.ok_at, p.error, p.reachable, p.via_bus = time.monotonic(), None, True, True
            p.polls += 1
        if was is False:
            self.emit("link_restored", f"vehicle {vid}: heard again on the fleet bus", vehicle=vid)
        self._watch(vid, prev, p.status)

    def silent_on_bus(self, vid: int, silent_s: float) -> None:
        """Nothing heard from vehicle ``vid`` on the bus for ``silent_s``: unreachable (once)."""
        with self._lock:
            p = self._polled.get(vid)
            if p is None or p.reachable is False:
                return
            p.reachable, p.error = False, f"nothing on the fleet bus for {silent_s:.1f} s"
        self.emit("link_lost", f"vehicle {vid}: companion silent on the fleet bus", severity="warning",
                  vehicle=vid)

    def _watch(self, vid: int, prev: dict[str, Any] | None, cur: dict[str, Any] | None) -> None:
        """Events from one poll to the next (seed 000 Sec. VII: the operator is told what needs him)."""
        if cur is None:
            return
        was_q = (prev or {}).get("queue", {})
        q = cur.get("queue", {})
        if waits_for_operator(cur) and not waits_for_operator(prev):
            self.emit("confirmation_required", f"vehicle {vid} waits for the operator's confirmation",
                      severity="warning", vehicle=vid)
        if q.get("queue_system_status") == "OVERRIDDEN" and was_q.get("queue_system_status") != "OVERRIDDEN":
            reason = cur.get("flight", {}).get("override_reason")
            self.emit("override", f"vehicle {vid} overridden: {reason}", severity="warning", vehicle=vid)
        mode = cur.get("vehicle", {}).get("mode")
        was_mode = (prev or {}).get("vehicle", {}).get("mode")
        if prev is not None and mode != was_mode and mode in FAILSAFE_MODES:
            why = self._commanded_by_operator(vid)
            if why is not None:  # the operator's own verb: history, not a failsafe alert
                self.emit("mode", f"vehicle {vid} switched to {mode} (from {was_mode}): the operator's {why}",
                          vehicle=vid, data={"mode": mode, "from": was_mode, "commanded": why})
            else:
                self.emit("failsafe", f"vehicle {vid} switched to {mode} (from {was_mode})",
                          severity="warning", vehicle=vid, data={"mode": mode, "from": was_mode})
        if cur.get("vehicle", {}).get("armed") is False:
            with self._lock:
                self._commanded.pop(vid, None)

    def commanded(self, vid: int, verb: str) -> None:
        """The operator's ``verb`` (rtl, land) was accepted by vehicle ``vid``'s companion: its coming
        switches to RTL/LAND are that verb, not a failsafe (until it disarms, at most :data:`COMMANDED_S`)."""
        with self._lock:
            self._commanded[vid] = (time.monotonic(), verb)

    def _commanded_by_operator(self, vid: int) -> str | None:
        with self._lock:
            t, verb = self._commanded.get(vid, (-math.inf, ""))
        return verb if time.monotonic() - t < COMMANDED_S else None

    def duplicates(self) -> dict[int, Any]:
        """Vehicle -> what its companion's status says of a duplicate id (its team member refused to join:
        ``team.team`` is ``"refused: duplicate id N ..."``; or ``team.duplicate_id``), for the vehicles
        whose companion says so."""
        with self._lock:
            statuses = {v: p.status for v, p in self._polled.items() if p.status}
        out = {}
        for vid, st in statuses.items():
            team = st.get("team") if isinstance(st, dict) else None
            dup = team.get("duplicate_id") if isinstance(team, dict) else None
            joined = team.get("team") if isinstance(team, dict) else None
            if not dup and isinstance(joined, str) and joined.startswith("refused") and "duplicate" in joined:
                dup = joined
            if dup:
                out[vid] = dup
        return out

    # --- the merged view -------------------------------------------------------------------------------
    def snapshot(self, max_age_s: float = 0.05) -> list[dict[str, Any]]:
        """One record per vehicle (the fields of :class:`~groundstation.schemas.VehicleOut`); a snapshot
        at most ``max_age_s`` old is shared (the REST readers and the WebSocket broadcast)."""
        now = time.monotonic()
        at, cached = self._cache
        if now - at <= max_age_s:
            return cached
        out = self._build(now)
        self._cache = (now, out)
        return out

    def _build(self, now: float) -> list[dict[str, Any]]:
        rows = self.station.state.entries()
        with self._lock:
            registry = dict(self.registry)
            polled = {v: Polled(p.status, p.mission, p.ok_at, p.error, p.reachable, via_bus=p.via_bus)
                      for v, p in self._polled.items()}
            for m, e in rows.items():
                seen = self._seen.setdefault(m, _Seen())
                if (e.stamp, e.seq) != (seen.stamp, seen.seq):
                    seen.stamp, seen.seq, seen.at = e.stamp, e.seq, now
            seen_at = {m: s.at for m, s in self._seen.items()}
        out = []
        heard = {m for m, e in rows.items() if e.status is not MemberStatus.STATION}
        for vid in sorted(set(registry) | heard):
            out.append(self._record(vid, registry.get(vid, Registered()), rows.get(vid), polled.get(vid),
                                    seen_at.get(vid), now))
        return out

    def _record(self, vid: int, reg: Registered, row: MemberEntry | None, p: Polled | None,
                seen_at: float | None, now: float) -> dict[str, Any]:
        status = p.status if p is not None else None
        veh = (status or {}).get("vehicle", {})
        queue = (status or {}).get("queue", {})
        position = velocity = None
        if row is not None and row.voc > 0:
            position = {"lat": row.position[0], "lon": row.position[1], "alt": row.position[2]}
            velocity = list(row.velocity)
        elif veh.get("global_position"):
            g = veh["global_position"]
            position = {"lat": g[0], "lon": g[1], "alt": g[3]}
        if velocity is None and veh.get("velocity"):
            velocity = list(veh["velocity"])
        att = veh.get("attitude")
        heading = math.degrees(att[2]) % 360.0 if att else None
        times = [t for t in (seen_at, p.ok_at if p and p.ok_at else None) if t]
        age = round(now - max(times), 3) if times else None
        if row is None:
            team_state = "unknown"
        elif row.voc == 0:
            team_state = "gone"
        else:
            team_state = "available" if row.status.available else "taken"
        mission: dict[str, Any] = {"state": None, "node": None, "progress": None}
        if p is not None and p.mission:
            m = p.mission
            mission = {"state": m.get("state"), "node": m.get("active_node"),
                       "progress": _progress(m.get("tree"), m.get("active_node"))}
        reachable = p is not None and p.reachable
        known = reg.control_url or (p is not None and p.via_bus)
        companion = "none" if not known else ("ok" if reachable else "unreachable")
        rec = {
            "id": vid, "name": reg.name or (row.name if row is not None else "") or f"vehicle {vid}",
            "control_url": reg.control_url, "position": position, "velocity": velocity, "heading": heading,
            "mode": veh.get("mode"), "armed": veh.get("armed"), "battery": veh.get("battery_remaining"),
            "battery_voltage": veh.get("battery_voltage"), "age_s": age, "team_state": team_state,
            "member_status": row.status.name.lower() if row is not None else None,
            "task": (row.task or None) if row is not None else None,
            "claims": [{"task": c.task, "version": c.version, "cost": round(c.cost, 2),
                        "state": c.state.name.lower()} for c in row.claims] if row is not None else [],
            "mission": mission, "queue_status": queue.get("queue_status"),
            "confirmation_required": waits_for_operator(status),
            "companion": companion,
        }
        rec["health"] = health(rec, veh, queue, p)
        return rec


def waits_for_operator(status: dict[str, Any] | None) -> bool:
    """The vehicle waits for the operator's confirmation: the companion's executive layer says so
    (``awaits_operator``: not an idle vehicle's default hover, which also ends on E_User); a companion
    without one, by the QAPI flag alone (``confirmation_required_status``, seed 000 Sec. IV-A)."""
    if not status:
        return False
    if status.get("awaits_operator") is not None:
        return bool(status["awaits_operator"])
    return bool(status.get("queue", {}).get("confirmation_required_status"))


def _progress(tree: dict[str, Any] | None, active: str | None) -> str | None:
    if not tree or not active:
        return None
    stack = [tree]
    while stack:
        n = stack.pop()
        if n.get("id") == active:
            prog = n.get("progress") or {}
            return prog.get("text") if isinstance(prog, dict) else None
        stack += [c for c in n.get("children") or [] if isinstance(c, dict)]
    return None


def health(rec: dict[str, Any], veh: dict[str, Any], queue: dict[str, Any], p: Polled | None
           ) -> dict[str, Any]:
    """Green / yellow / red with the reasons (red: act now; yellow: look)."""
    red: list[str] = []
    yellow: list[str] = []
    if rec["team_state"] == "gone":
        red.append("gone from the team link")
    if rec["companion"] == "unreachable":
        red.append(f"companion unreachable{': ' + p.error if p and p.error else ''}")
    age = rec["age_s"]
    if age is not None and age > LOST_S:
        red.append(f"nothing heard for {age:.1f} s")
    elif age is not None and age > STALE_S:
        yellow.append(f"last message {age:.1f} s old")
    if rec["member_status"] == "overridden" or queue.get("queue_system_status") == "OVERRIDDEN":
        red.append("overridden by a ground station")
    batt = rec["battery"]
    if isinstance(batt, int | float) and batt >= 0:
        if batt < BATTERY_CRITICAL:
            red.append(f"battery {batt:.0f} %")
        elif batt < BATTERY_LOW:
            yellow.append(f"battery {batt:.0f} %")
    if rec["mode"] in FAILSAFE_MODES and rec["armed"]:
        yellow.append(f"mode {rec['mode']}")
    if rec["confirmation_required"]:
        yellow.append("waiting for the operator's confirmation")
    if rec["team_state"] == "taken":
        yellow.append("out of the team (taken)")
    fix = veh.get("gps_fix_type")
    if isinstance(fix, int) and fix < 3:
        yellow.append(f"GPS fix type {fix}")
    if queue.get("limit_reached"):
        yellow.append("a limit was reached")
    if rec["team_state"] == "unknown" and rec["companion"] == "none":
        yellow.append("never heard")
    level = "red" if red else "yellow" if yellow else "green"
    return {"level": level, "reasons": red + yellow}
