"""The ground service's database and live stream under load and failure.

* the schema has a version; a file of the service before versions (version 0, its tables made here with
  the old statements) is migrated to the current one with its rows kept; a newer file is refused;
* a task event writes that task (one row), not every task of the ledger (SQLite's statement trace);
* a write that fails (the connection made read-only under the running service) answers 503 and nothing
  of it is stored, published to the team or registered;
* a restarted service brings the open tasks of the earlier run back held: off the board the team
  floods, until released (or ``resume_tasks``);
* alerts: battery low / critical, link lost (not heard), duplicate id, each once a crossing; the history
  after a reconnect (``GET /api/alerts``), the acknowledgement stored, audited, sent to every client;
* the telemetry kept at ~1 Hz and a vehicle's track read back between two times; retention prunes;
* a WebSocket client that stops reading is sent the newest snapshot when it reads again, not a backlog.
"""

from __future__ import annotations

import json
import socket
import sqlite3
import time
from pathlib import Path
from typing import Any

import pytest
from websockets.sync.client import connect

from companion.team.tasks import TaskDef
from groundstation.alerts import AlertWatch
from groundstation.auth import Tokens
from groundstation.db import Database
from groundstation.migrations import VERSION
from groundstation.service import GroundService, Retention
from harness.ground import OPERATOR, TOKENS, InProcessGround
from harness.team import new_team_url

#: the tables of the service before schema versions (main of 2026-11-28), as it created them
OLD_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS tasks (
    id INTEGER PRIMARY KEY, grp INTEGER NOT NULL, kind TEXT NOT NULL, state TEXT NOT NULL,
    holder INTEGER, cost REAL, version INTEGER NOT NULL, name TEXT NOT NULL, task TEXT NOT NULL,
    updated REAL NOT NULL);
CREATE TABLE IF NOT EXISTS task_groups (
    id INTEGER PRIMARY KEY, defn TEXT NOT NULL, pieces TEXT NOT NULL, updated REAL NOT NULL);
CREATE TABLE IF NOT EXISTS assignments (
    id INTEGER PRIMARY KEY AUTOINCREMENT, t REAL NOT NULL, task INTEGER NOT NULL, state TEXT NOT NULL,
    holder INTEGER);
CREATE TABLE IF NOT EXISTS missions (
    id INTEGER PRIMARY KEY AUTOINCREMENT, t REAL NOT NULL, vehicle INTEGER NOT NULL, mission TEXT NOT NULL,
    status INTEGER NOT NULL, answer TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS vehicles (
    id INTEGER PRIMARY KEY, name TEXT NOT NULL, control_url TEXT, registered REAL NOT NULL);
CREATE TABLE IF NOT EXISTS audit (
    id INTEGER PRIMARY KEY AUTOINCREMENT, t REAL NOT NULL, who TEXT NOT NULL, role TEXT NOT NULL,
    action TEXT NOT NULL, target TEXT NOT NULL, body TEXT, status INTEGER NOT NULL, answer TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS events (
    id INTEGER PRIMARY KEY AUTOINCREMENT, t REAL NOT NULL, kind TEXT NOT NULL, severity TEXT NOT NULL,
    vehicle INTEGER, task INTEGER, message TEXT NOT NULL, data TEXT NOT NULL);
"""
VISIT = TaskDef("visit", ((47.397742, 8.545594, 6.0),))


def service(tmp: Path, **kw: Any) -> GroundService:
    """A service on ``tmp/ground.db`` on a team link of its own (not started: nothing polls or floods)."""
    return GroundService(str(tmp / "ground.db"), Tokens(TOKENS), team_url=new_team_url(), **kw)


def test_a_version_0_database_is_migrated_with_its_rows_and_a_newer_one_refused(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    old = sqlite3.connect(path)
    old.executescript(OLD_SCHEMA)
    old.execute("INSERT INTO events (t, kind, severity, vehicle, task, message, data) "
                "VALUES (1.0, 'failsafe', 'warning', 2, NULL, 'vehicle 2 switched to RTL', '{}')")
    old.execute("INSERT INTO vehicles (id, name, control_url, registered) VALUES (2, 'two', NULL, 1.0)")
    old.commit()
    assert old.execute("PRAGMA user_version").fetchone()[0] == 0
    old.close()

    db = Database(path)
    assert db.migrated == (0, VERSION) and db.version == VERSION == 2
    [ev] = db.events()
    assert ev["kind"] == "failsafe" and ev["acked_by"] is None and ev["data"] == {}
    assert db.vehicles() == [{"id": 2, "name": "two", "control_url": None}]
    assert db.ack_event(ev["id"], "op")["acked_by"] == "op"
    db.add_telemetry([(5.0, 2, 47.0, 8.0, 3.0, 90.0, "GUIDED", 1, 80.0, "green")])
    assert db.track(2, 0.0, 10.0)[0]["armed"] is True
    db.close()
    again = Database(path)  # already current: nothing to do
    assert again.migrated == (VERSION, VERSION)
    again.close()

    newer = sqlite3.connect(path)
    newer.execute(f"PRAGMA user_version = {VERSION + 1}")
    newer.close()
    with pytest.raises(ValueError, match="newer than this service"):
        Database(path)


def test_a_task_event_writes_that_task_not_the_ledger(tmp_path: Path) -> None:
    svc = service(tmp_path)
    try:
        for _ in range(50):
            svc.station.add(VISIT)
        tid = svc.station.ledger.ids()[10]
        statements: list[str] = []
        svc.db._db.set_trace_callback(statements.append)
        svc.station.ledger.assign(tid, 3, time.time())  # what the follow-up does when a vehicle claims it
        svc._on_station({"t": time.time(), "event": "task", "task": tid, "state": "assigned", "holder": 3})
        svc.db._db.set_trace_callback(None)
        task_writes = [s for s in statements if s.lstrip().upper().startswith("INSERT INTO TASKS")]
        assert len(task_writes) == 1, f"{len(task_writes)} task rows written for one task event"
        row = next(r for r in svc.db.tasks() if r["id"] == tid)
        assert (row["state"], row["holder"]) == ("assigned", 3)
        assert [a["holder"] for a in svc.db.assignments(tid)][-1] == 3
    finally:
        svc.close()


@pytest.mark.integration
def test_a_failed_write_answers_503_and_nothing_is_half_done(tmp_path: Path) -> None:
    g = InProcessGround(tmp_path)
    svc = g.service
    try:
        with g.http() as c:
            first = c.post("/api/tasks", json={"type": "visit", "point": [47.3977, 8.5456, 6]})
            assert first.status_code == 201
            board_before = svc.station.state.board
            tasks_before = c.get("/api/tasks").json()["tasks"]
            svc.db._db.execute("PRAGMA query_only = ON")  # every write of the service fails from here
            r = c.post("/api/tasks", json={"type": "visit", "point": [47.3978, 8.5457, 6]})
            assert r.status_code == 503 and "not stored" in r.json()["error"], r.text
            assert c.get("/api/tasks").json()["tasks"] == tasks_before  # nothing added in memory either
            assert svc.station.state.board.tasks == board_before.tasks  # nor published to the team
            r = c.delete(f"/api/tasks/{tasks_before[0]['id']}")
            assert r.status_code == 503
            assert c.get("/api/tasks").json()["tasks"] == tasks_before
            assert c.put("/api/vehicles/9", json={"name": "nine"}).status_code == 503
            assert all(v["id"] != 9 for v in c.get("/api/vehicles").json()["vehicles"])
            svc.db._db.execute("PRAGMA query_only = OFF")
            assert c.delete(f"/api/tasks/{tasks_before[0]['id']}").status_code == 200
        stored = {r["id"]: r["state"] for r in Database(tmp_path / "ground.db").tasks()}
        assert stored == {tasks_before[0]["id"]: "cancelled"}
    finally:
        g.close()


def test_restored_open_tasks_come_back_held_off_the_board_until_released(tmp_path: Path) -> None:
    first = service(tmp_path)
    done_id = first.station.add(VISIT).ids[0]
    first.station.cancel(done_id)
    open_ids = [first.station.add(VISIT).ids[0] for _ in range(2)]
    first.close()

    svc = service(tmp_path)
    try:
        views = {t["id"]: t["state"] for t in svc.tasks()}
        assert views == {done_id: "cancelled", open_ids[0]: "held", open_ids[1]: "held"}
        svc.station.step()  # nobody heard: nothing of the earlier run is kept
        assert svc.station.held() == tuple(open_ids)
        assert {t.id for t in svc.station.state.board.tasks} <= {done_id}  # the team is not given them
        with pytest.raises(Exception, match="not held"):
            svc.release_tasks([done_id])
        assert svc.release_tasks([open_ids[0]]) == [open_ids[0]]
        board = svc.station.state.board
        assert open_ids[0] in {t.id for t in board.tasks} and open_ids[1] not in {t.id for t in board.tasks}
        assert {t["id"]: t["state"] for t in svc.tasks()}[open_ids[0]] == "unassigned"
        kinds = [e["kind"] for e in svc.db.events()]
        assert "restored" in kinds and "tasks_released" in kinds
    finally:
        svc.close()
    resumed = service(tmp_path, resume_tasks=True)
    try:
        assert resumed.station.held() == ()
        assert set(open_ids) <= {t.id for t in resumed.station.state.board.tasks}
    finally:
        resumed.close()


def test_alerts_are_derived_once_a_crossing() -> None:
    got: list[tuple[str, int | None]] = []
    watch = AlertWatch(lambda kind, message, **kw: got.append((kind, kw.get("vehicle"))))

    def rec(vid: int, battery: float | None, age: float | None) -> dict[str, Any]:
        return {"id": vid, "name": "", "battery": battery, "age_s": age}

    watch.look([rec(1, 80, 0.1), rec(2, 50, 0.1)])
    watch.look([rec(1, 25, 0.1), rec(2, 50, 6.0)], {2: "taken by another member"})
    watch.look([rec(1, 24, 0.2), rec(2, 50, 7.0)], {2: "taken by another member"})  # nothing new
    watch.look([rec(1, 10, 0.2), rec(2, 50, 0.3)])
    watch.look([rec(1, 31, 0.2), rec(2, 50, 0.3)])  # back above low + hysteresis: re-armed
    watch.look([rec(1, 20, 0.2)])
    assert got == [("battery_low", 1), ("link_lost", 2), ("duplicate_id", 2), ("battery_critical", 1),
                   ("link_restored", 2), ("battery_low", 1)]


@pytest.mark.integration
def test_alert_history_acknowledgement_and_the_track(tmp_path: Path) -> None:
    g = InProcessGround(tmp_path)
    svc = g.service
    try:
        svc.emit("failsafe", "vehicle 2 switched to RTL", severity="warning", vehicle=2)
        svc.emit("task_added", "not an alert")
        now = time.time()
        svc.db.add_telemetry([(now - 30 + i, 2, 47.0 + i * 1e-5, 8.0, 5.0, 0.0, "GUIDED", 1, 70.0, "green")
                              for i in range(20)])
        with g.http() as c, g.ws() as ws:
            assert json.loads(ws.recv(10))["type"] == "hello"
            alerts = c.get("/api/alerts").json()
            assert [a["kind"] for a in alerts["alerts"]] == ["failsafe"] and "battery_low" in alerts["kinds"]
            eid = alerts["alerts"][0]["id"]
            r = c.post(f"/api/events/{eid}/ack")
            assert r.status_code == 200 and r.json()["acked_by"].startswith("operator")
            first_at = r.json()["acked_at"]
            # the first ack among the next 200 messages (snapshots at 10 Hz in between)
            ack = next((m for m in (json.loads(ws.recv(10)) for _ in range(200)) if m["type"] == "ack"), None)
            assert ack and ack["id"] == eid and ack["acked_by"] == r.json()["acked_by"]
            assert c.post(f"/api/events/{eid}/ack").json()["acked_at"] == first_at  # the first one stays
            assert c.post("/api/events/999999/ack").status_code == 404
            # after a reload too
            assert c.get("/api/alerts").json()["alerts"][0]["acked_by"] == r.json()["acked_by"]
            assert [e["action"] for e in c.get("/api/audit").json()["entries"]].count("ack") == 3
            track = c.get("/api/track/2", params={"since": now - 25, "until": now}).json()["points"]
            assert len(track) == 15 and track[0]["t"] < track[-1]["t"] and track[0]["mode"] == "GUIDED"
            assert c.get("/api/track/2", params={"since": now, "until": now - 10}).status_code == 400
    finally:
        g.close()


def test_retention_prunes_events_and_telemetry_by_age(tmp_path: Path) -> None:
    db = Database(tmp_path / "g.db")
    now = time.time()
    db.add_event("old", "x", t=now - 100)
    db.add_event("new", "y", t=now)
    db.add_telemetry([(now - 100, 1, 0, 0, 0, 0, "G", 1, 1, "green"),
                      (now, 1, 0, 0, 0, 0, "G", 1, 1, "green")])
    db.audit("op", "operator", "land", "vehicle 1", None, 200, {})
    assert db.prune(events_keep_s=50, telemetry_keep_s=50, now=now) == (1, 1)
    assert [e["kind"] for e in db.events()] == ["new"] and len(db.track(1, 0, now + 1)) == 1
    assert len(db.audit_log()) == 1  # commands are never pruned
    with pytest.raises(ValueError, match="telemetry_keep_s"):
        Retention(telemetry_keep_s=0)
    db.close()


@pytest.mark.integration
def test_a_slow_websocket_client_gets_the_newest_snapshot_not_a_backlog(tmp_path: Path) -> None:
    """60 vehicles registered make each snapshot ~40 kB; the client reads nothing for 5 s (100 snapshots
    at 20 Hz), then reads on: the snapshots it is sent are the newest, the few old ones are only those
    the sockets' buffers already held (before: every one of the 100, queued for it)."""
    g = InProcessGround(tmp_path, snapshot_period_s=0.05)
    try:
        for vid in range(1, 61):
            g.service.register(vid, f"vehicle number {vid}", None)
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 32768)  # a client's buffers, not the kernel's
        sock.connect(("127.0.0.1", int(g.url.rsplit(":", 1)[1])))
        url = g.url.replace("http://", "ws://") + f"/api/ws?token={OPERATOR}"
        # without compression, so that the buffers hold what a slow link holds (compressed ~30:1, a
        # 64 kB receive queue already holds a hundred of these repetitive snapshots)
        with connect(url, sock=sock, max_queue=2, open_timeout=10, compression=None) as ws:
            assert json.loads(ws.recv(10))["type"] == "hello"
            time.sleep(5.0)  # the stall being tested: the client reads nothing (100 snapshot periods)
            resumed = time.time()
            old = 0
            while True:
                msg = json.loads(ws.recv(10))
                if msg["type"] != "snapshot":
                    continue
                if msg["t"] >= resumed - 0.25:
                    break
                old += 1
            assert old < 30, f"{old} old snapshots sent after the stall (a backlog; 94 before)"
    finally:
        g.close()
