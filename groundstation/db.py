"""The ground service's database: everything the operator said and the team did.

Seed 000 Sec. VII and seed 003 Sec. II give the operator the team's tasks and the vehicles' missions;
killed and restarted, the ground service must lose none of it. One SQLite file in WAL mode (the
standard :mod:`sqlite3` module), written synchronously on every change, holds

* ``tasks``: every allocatable task (a piece of a divided task too) with its state, holder, cost and
  the full :class:`~companion.team.types.TeamTask` (JSON), and ``task_groups``: the operator's
  definitions of divided tasks with their pieces; ``meta``: the ledger's next id and board (stamp, seq);
  together they rebuild the station's :class:`~companion.team.tasks.TaskLedger` (:meth:`Database.ledger`);
* ``assignments``: the history of each task's state and holder;
* ``missions``: the missions given to vehicles and the answers;
* ``vehicles``: the registry (id, name, the companion's control URL);
* ``audit``: every operator command (who, role, what, when, the answer), refusals included;
* ``events``: alerts and history (failsafe, override, link lost, confirmation required, task changes).

Thread-safe: one connection behind a lock (the writes are small and few).
"""

from __future__ import annotations

import dataclasses
import json
import sqlite3
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from companion.team.tasks import LedgerSnapshot, TaskDef
from companion.team.types import TaskKind, TaskState, TeamTask

SCHEMA = """
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


def task_to_json(t: TeamTask) -> str:
    d = dataclasses.asdict(t)
    d["kind"], d["state"] = t.kind.value, t.state.value
    return json.dumps(d)


def task_from_json(text: str) -> TeamTask:
    d = json.loads(text)
    d["kind"], d["state"] = TaskKind(d["kind"]), TaskState(d["state"])
    d["points"] = tuple(tuple(float(v) for v in p) for p in d["points"])
    return TeamTask(**d)


def defn_to_json(defn: TaskDef) -> str:
    d = dataclasses.asdict(defn)
    d["tree"] = dict(defn.tree) if defn.tree is not None else None
    return json.dumps(d)


def defn_from_json(text: str) -> TaskDef:
    d = json.loads(text)
    d["points"] = tuple(tuple(float(v) for v in p) for p in d["points"])
    return TaskDef(**d)


class Database:
    """See module docstring. ``path``: the SQLite file (created with its tables if absent)."""

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        self._lock = threading.Lock()
        self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        self._db.row_factory = sqlite3.Row
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")  # WAL: durable across a killed process
        self._db.executescript(SCHEMA)

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def _write(self, sql: str, args: Iterable[Any] = ()) -> int:
        with self._lock:
            cur = self._db.execute(sql, tuple(args))
            return int(cur.lastrowid or 0)

    def _read(self, sql: str, args: Iterable[Any] = ()) -> list[dict[str, Any]]:
        with self._lock:
            return [dict(r) for r in self._db.execute(sql, tuple(args)).fetchall()]

    # --- the task ledger ----------------------------------------------------------------------------
    def save_ledger(self, snap: LedgerSnapshot, costs: dict[int, float | None] | None = None) -> None:
        """Write the whole ledger in one transaction (tasks are upserted; none is ever deleted)."""
        now = time.time()
        costs = costs or {}
        with self._lock:
            self._db.execute("BEGIN")
            try:
                for task, state, holder in snap.tasks:
                    self._db.execute(
                        "INSERT INTO tasks (id, grp, kind, state, holder, cost, version, name, task, updated)"
                        " VALUES (?,?,?,?,?,?,?,?,?,?) ON CONFLICT(id) DO UPDATE SET state=excluded.state, "
                        "holder=excluded.holder, cost=excluded.cost, version=excluded.version, "
                        "task=excluded.task, updated=excluded.updated",
                        (task.id, task.group, task.kind.value, TaskState(state).value, holder,
                         costs.get(task.id), task.version, task.name, task_to_json(task), now))
                for gid, defn, pieces in snap.groups:
                    self._db.execute(
                        "INSERT INTO task_groups (id, defn, pieces, updated) VALUES (?,?,?,?) "
                        "ON CONFLICT(id) DO UPDATE SET defn=excluded.defn, pieces=excluded.pieces, "
                        "updated=excluded.updated", (gid, defn_to_json(defn), json.dumps(list(pieces)), now))
                for key, value in (("next_id", snap.next_id), ("seq", snap.seq), ("stamp", snap.stamp)):
                    self._db.execute("INSERT INTO meta (key, value) VALUES (?, ?) ON CONFLICT(key) "
                                     "DO UPDATE SET value=excluded.value", (key, json.dumps(value)))
                self._db.execute("COMMIT")
            except BaseException:
                self._db.execute("ROLLBACK")
                raise

    def ledger(self) -> LedgerSnapshot | None:
        """The saved ledger, or None for a new database."""
        meta = {r["key"]: json.loads(r["value"]) for r in self._read("SELECT key, value FROM meta")}
        if "next_id" not in meta:
            return None
        tasks = tuple((task_from_json(r["task"]), TaskState(r["state"]), r["holder"])
                      for r in self._read("SELECT task, state, holder FROM tasks ORDER BY id"))
        groups = tuple((r["id"], defn_from_json(r["defn"]), tuple(json.loads(r["pieces"])))
                       for r in self._read("SELECT id, defn, pieces FROM task_groups ORDER BY id"))
        return LedgerSnapshot(tasks=tasks, groups=groups, next_id=int(meta["next_id"]), seq=int(meta["seq"]),
                              stamp=float(meta["stamp"]))

    def tasks(self) -> list[dict[str, Any]]:
        return self._read("SELECT id, grp, kind, state, holder, cost, version, name FROM tasks ORDER BY id")

    # --- histories ------------------------------------------------------------------------------------
    def add_assignment(self, task: int, state: str, holder: int | None, t: float | None = None) -> None:
        self._write("INSERT INTO assignments (t, task, state, holder) VALUES (?,?,?,?)",
                    (t if t is not None else time.time(), task, state, holder))

    def assignments(self, task: int | None = None) -> list[dict[str, Any]]:
        if task is None:
            return self._read("SELECT * FROM assignments ORDER BY id")
        return self._read("SELECT * FROM assignments WHERE task = ? ORDER BY id", (task,))

    def add_mission(self, vehicle: int, mission: Any, status: int, answer: Any) -> int:
        return self._write("INSERT INTO missions (t, vehicle, mission, status, answer) VALUES (?,?,?,?,?)",
                           (time.time(), vehicle, json.dumps(mission), status, json.dumps(answer)))

    def missions(self, vehicle: int | None = None) -> list[dict[str, Any]]:
        rows = (self._read("SELECT * FROM missions ORDER BY id") if vehicle is None else
                self._read("SELECT * FROM missions WHERE vehicle = ? ORDER BY id", (vehicle,)))
        for r in rows:
            r["mission"], r["answer"] = json.loads(r["mission"]), json.loads(r["answer"])
        return rows

    def audit(self, who: str, role: str, action: str, target: str, body: Any, status: int, answer: Any
              ) -> int:
        return self._write("INSERT INTO audit (t, who, role, action, target, body, status, answer) "
                           "VALUES (?,?,?,?,?,?,?,?)", (time.time(), who, role, action, target,
                                                        json.dumps(body), status, json.dumps(answer)))

    def audit_log(self, since: int = 0, limit: int = 1000) -> list[dict[str, Any]]:
        rows = self._read("SELECT * FROM audit WHERE id > ? ORDER BY id LIMIT ?", (since, limit))
        for r in rows:
            r["body"], r["answer"] = json.loads(r["body"] or "null"), json.loads(r["answer"])
        return rows

    def add_event(self, kind: str, message: str, *, severity: str = "info", vehicle: int | None = None,
                  task: int | None = None, data: dict[str, Any] | None = None, t: float | None = None) -> int:
        return self._write("INSERT INTO events (t, kind, severity, vehicle, task, message, data) "
                           "VALUES (?,?,?,?,?,?,?)", (t if t is not None else time.time(), kind, severity,
                                                      vehicle, task, message, json.dumps(data or {})))

    def events(self, since: int = 0, limit: int = 1000, kind: str | None = None) -> list[dict[str, Any]]:
        if kind is None:
            rows = self._read("SELECT * FROM events WHERE id > ? ORDER BY id LIMIT ?", (since, limit))
        else:
            rows = self._read("SELECT * FROM events WHERE id > ? AND kind = ? ORDER BY id LIMIT ?",
                              (since, kind, limit))
        for r in rows:
            r["data"] = json.loads(r["data"])
        return rows

    # --- the vehicle registry ---------------------------------------------------------------------------
    def put_vehicle(self, vid: int, name: str, control_url: str | None) -> None:
        self._write("INSERT INTO vehicles (id, name, control_url, registered) VALUES (?,?,?,?) "
                    "ON CONFLICT(id) DO UPDATE SET name=excluded.name, control_url=excluded.control_url",
                    (vid, name, control_url, time.time()))

    def vehicles(self) -> list[dict[str, Any]]:
        return self._read("SELECT id, name, control_url FROM vehicles ORDER BY id")
