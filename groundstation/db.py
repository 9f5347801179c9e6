"""The ground service's database: everything the operator said and the team did.

Seed 000 Sec. VII and seed 003 Sec. II give the operator the team's tasks and the vehicles' missions;
killed and restarted, the ground service must lose none of it. One SQLite file in WAL mode (the
standard :mod:`sqlite3` module), written synchronously (``synchronous=FULL``) on every change, holds

* ``tasks``: every allocatable task (a piece of a divided task too) with its state, holder, cost and
  the full :class:`~companion.team.types.TeamTask` (JSON), and ``task_groups``: the operator's
  definitions of divided tasks with their pieces; ``meta``: the ledger's next id and board (stamp, seq);
  together they rebuild the station's :class:`~companion.team.tasks.TaskLedger` (:meth:`Database.ledger`);
* ``assignments``: the history of each task's state and holder;
* ``missions``: the missions given to vehicles and the answers;
* ``vehicles``: the registry (id, name, the companion's control URL);
* ``audit``: every operator command (who, role, what, when, the answer), refusals included;
* ``events``: alerts and history (failsafe, override, link lost, battery, duplicate id, confirmation
  required, task changes), each alert acknowledged once (who, when);
* ``telemetry``: each vehicle's position and status at about 1 Hz (the replay of a track).

The schema has a version (``PRAGMA user_version``) and numbered migrations (:mod:`.migrations`). Every
write is one transaction: all of it or nothing, and a failed one raises :class:`StorageError` (an
:class:`ApiError` 503) instead of being swallowed. A task event writes its task (:meth:`Database.save_tasks`),
never the whole ledger. Events and telemetry are pruned by age (:meth:`Database.prune`); commands, tasks
and missions are kept.

Thread-safe: each connection behind its lock (the writes are small).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import sqlite3
import threading
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from companion.team.tasks import LedgerSnapshot, TaskDef
from companion.team.types import TaskKind, TaskState, TeamTask
from taskflight_common.httpapi import ApiError

from .migrations import migrate

log = logging.getLogger(__name__)

#: a saved task: (task, ledger state, holder, cost)
TaskRow = tuple[TeamTask, TaskState, "int | None", "float | None"]

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


class StorageError(ApiError):
    """A database write that failed (503): the transaction was rolled back, nothing of it is stored."""

    def __init__(self, what: str, exc: BaseException) -> None:
        super().__init__(503, f"database: {what} not stored ({type(exc).__name__}: {exc})")


class Database:
    """See module docstring. ``path``: the SQLite file (created, or migrated to the current schema
    version, :mod:`groundstation.migrations`). Two connections: the commands, tasks, registry, audit and
    events one with ``synchronous=FULL`` (each commit on disk before the answer), and the telemetry one
    with ``synchronous=NORMAL`` (1 Hz samples, one transaction a second; a crash loses at most the last)."""

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        self._lock = threading.Lock()
        self._db = self._connect("FULL")
        self.migrated = migrate(self._db)
        self._tlock = threading.Lock()
        self._tdb = self._connect("NORMAL")

    def _connect(self, synchronous: str) -> sqlite3.Connection:
        db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None, timeout=10.0)
        db.row_factory = sqlite3.Row
        db.execute("PRAGMA journal_mode=WAL")
        db.execute(f"PRAGMA synchronous={synchronous}")
        return db

    @property
    def version(self) -> int:
        return int(self._read("PRAGMA user_version")[0]["user_version"])

    def close(self) -> None:
        with self._lock, self._tlock:
            self._db.close()
            self._tdb.close()

    @contextmanager
    def transaction(self, what: str) -> Iterator[sqlite3.Connection]:
        """One write transaction on the FULL connection: all of it or nothing (StorageError, 503)."""
        with self._lock:
            try:
                self._db.execute("BEGIN IMMEDIATE")
            except sqlite3.Error as exc:
                raise StorageError(what, exc) from exc
            try:
                yield self._db
                self._db.execute("COMMIT")
            except BaseException as exc:
                try:
                    self._db.execute("ROLLBACK")
                except sqlite3.Error:
                    log.exception("database: rollback of %s failed", what)
                if isinstance(exc, sqlite3.Error):
                    raise StorageError(what, exc) from exc
                raise

    def _write(self, sql: str, args: Iterable[Any] = (), what: str = "write") -> int:
        with self.transaction(what) as db:
            cur = db.execute(sql, tuple(args))
            return int(cur.lastrowid or 0)

    def _read(self, sql: str, args: Iterable[Any] = ()) -> list[dict[str, Any]]:
        with self._lock:
            try:
                return [dict(r) for r in self._db.execute(sql, tuple(args)).fetchall()]
            except sqlite3.Error as exc:
                raise ApiError(503, f"database: read failed ({type(exc).__name__}: {exc})") from exc

    # --- the task ledger ----------------------------------------------------------------------------
    def save_ledger(self, snap: LedgerSnapshot, costs: dict[int, float | None] | None = None) -> None:
        """Write the whole ledger in one transaction (a restore; tasks are upserted, none deleted)."""
        costs = costs or {}
        self.save_tasks([(t, s, h, costs.get(t.id)) for t, s, h in snap.tasks], snap.groups,
                        {"next_id": snap.next_id, "seq": snap.seq, "stamp": snap.stamp})

    def save_tasks(self, tasks: Iterable[TaskRow],
                   groups: Iterable[tuple[int, TaskDef, tuple[int, ...]]] = (),
                   meta: dict[str, Any] | None = None,
                   assignments: Iterable[tuple[int, str, int | None, float | None]] = ()) -> None:
        """Write these tasks (and groups, meta keys, assignment history rows) in one transaction: a
        task event writes its task, not the ledger. StorageError (nothing written) on failure."""
        now = time.time()
        with self.transaction("tasks") as db:
            for task, state, holder, cost in tasks:
                db.execute(
                    "INSERT INTO tasks (id, grp, kind, state, holder, cost, version, name, task, updated)"
                    " VALUES (?,?,?,?,?,?,?,?,?,?) ON CONFLICT(id) DO UPDATE SET state=excluded.state, "
                    "holder=excluded.holder, cost=excluded.cost, version=excluded.version, "
                    "task=excluded.task, updated=excluded.updated",
                    (task.id, task.group, task.kind.value, TaskState(state).value, holder, cost,
                     task.version, task.name, task_to_json(task), now))
            for gid, defn, pieces in groups:
                db.execute(
                    "INSERT INTO task_groups (id, defn, pieces, updated) VALUES (?,?,?,?) "
                    "ON CONFLICT(id) DO UPDATE SET defn=excluded.defn, pieces=excluded.pieces, "
                    "updated=excluded.updated", (gid, defn_to_json(defn), json.dumps(list(pieces)), now))
            for key, value in (meta or {}).items():
                db.execute("INSERT INTO meta (key, value) VALUES (?, ?) ON CONFLICT(key) "
                           "DO UPDATE SET value=excluded.value", (key, json.dumps(value)))
            for tid, change, who, t in assignments:
                db.execute("INSERT INTO assignments (t, task, state, holder) VALUES (?,?,?,?)",
                           (t if t is not None else now, tid, change, who))

    def ledger(self) -> LedgerSnapshot | None:
        """The saved ledger, or None for a new database."""
        meta = {r["key"]: json.loads(r["value"]) for r in self._read("SELECT key, value FROM meta")}
        if "next_id" not in meta:
            return None
        tasks = tuple((task_from_json(r["task"]), TaskState(r["state"]), r["holder"])
                      for r in self._read("SELECT task, state, holder FROM tasks ORDER BY id"))
        groups = tuple((r["id"], defn_from_json(r["defn"]), tuple(json.loads(r["pieces"])))
                       for r in self._read("SELECT id, defn, pieces FROM task_groups ORDER BY id"))
        top = max([t[0].id for t in tasks] + [g[0] for g in groups] + [0])
        return LedgerSnapshot(tasks=tasks, groups=groups, next_id=max(int(meta["next_id"]), top + 1),
                              seq=int(meta.get("seq", 0)), stamp=float(meta.get("stamp", 0.0)))

    def tasks(self) -> list[dict[str, Any]]:
        return self._read("SELECT id, grp, kind, state, holder, cost, version, name FROM tasks ORDER BY id")

    # --- histories ------------------------------------------------------------------------------------
    def add_assignment(self, task: int, state: str, holder: int | None, t: float | None = None) -> None:
        self._write("INSERT INTO assignments (t, task, state, holder) VALUES (?,?,?,?)",
                    (t if t is not None else time.time(), task, state, holder), "assignment")

    def assignments(self, task: int | None = None) -> list[dict[str, Any]]:
        if task is None:
            return self._read("SELECT * FROM assignments ORDER BY id")
        return self._read("SELECT * FROM assignments WHERE task = ? ORDER BY id", (task,))

    def add_mission(self, vehicle: int, mission: Any, status: int, answer: Any) -> int:
        return self._write("INSERT INTO missions (t, vehicle, mission, status, answer) VALUES (?,?,?,?,?)",
                           (time.time(), vehicle, json.dumps(mission), status, json.dumps(answer)), "mission")

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
                                                        json.dumps(body), status, json.dumps(answer)),
                           "audit")

    def audit_log(self, since: int = 0, limit: int = 1000) -> list[dict[str, Any]]:
        rows = self._read("SELECT * FROM audit WHERE id > ? ORDER BY id LIMIT ?", (since, limit))
        for r in rows:
            r["body"], r["answer"] = json.loads(r["body"] or "null"), json.loads(r["answer"])
        return rows

    # --- events and alerts ------------------------------------------------------------------------------
    def add_event(self, kind: str, message: str, *, severity: str = "info", vehicle: int | None = None,
                  task: int | None = None, data: dict[str, Any] | None = None, t: float | None = None) -> int:
        return self._write("INSERT INTO events (t, kind, severity, vehicle, task, message, data) "
                           "VALUES (?,?,?,?,?,?,?)", (t if t is not None else time.time(), kind, severity,
                                                      vehicle, task, message, json.dumps(data or {})),
                           "event")

    def events(self, since: int = 0, limit: int = 1000, kind: str | None = None,
               kinds: Iterable[str] | None = None, newest: bool = False) -> list[dict[str, Any]]:
        """Events after id ``since`` (oldest first); ``newest``: the last ``limit`` ones (still oldest
        first); ``kind`` / ``kinds``: only these."""
        where, args = ["id > ?"], [since]
        if kind is not None:
            where.append("kind = ?")
            args.append(kind)  # type: ignore[arg-type]
        if kinds is not None:
            ks = list(kinds)
            where.append(f"kind IN ({','.join('?' * len(ks))})")
            args += ks  # type: ignore[arg-type]
        order = "DESC" if newest else "ASC"
        rows = self._read(f"SELECT * FROM events WHERE {' AND '.join(where)} ORDER BY id {order} LIMIT ?",
                          (*args, limit))
        if newest:
            rows.reverse()
        for r in rows:
            r["data"] = json.loads(r["data"])
        return rows

    def ack_event(self, eid: int, who: str, t: float | None = None) -> dict[str, Any] | None:
        """Mark event ``eid`` acknowledged by ``who`` (the first acknowledgement stays); the row, or None
        for an unknown id."""
        with self.transaction("acknowledgement") as db:
            db.execute("UPDATE events SET acked_by = ?, acked_at = ? WHERE id = ? AND acked_by IS NULL",
                       (who, t if t is not None else time.time(), eid))
            row = db.execute("SELECT * FROM events WHERE id = ?", (eid,)).fetchone()
        if row is None:
            return None
        out = dict(row)
        out["data"] = json.loads(out["data"])
        return out

    # --- telemetry (the replay) ---------------------------------------------------------------------------
    def add_telemetry(self, rows: Iterable[tuple[Any, ...]]) -> None:
        """(t, vehicle, lat, lon, alt, heading, mode, armed, battery, health) rows, one transaction."""
        with self._tlock:
            try:
                self._tdb.execute("BEGIN")
                self._tdb.executemany("INSERT INTO telemetry (t, vehicle, lat, lon, alt, heading, mode, "
                                      "armed, battery, health) VALUES (?,?,?,?,?,?,?,?,?,?)", rows)
                self._tdb.execute("COMMIT")
            except sqlite3.Error as exc:
                with suppress_sqlite():
                    self._tdb.execute("ROLLBACK")
                raise StorageError("telemetry", exc) from exc

    def track(self, vehicle: int, t0: float, t1: float, limit: int = 20000) -> list[dict[str, Any]]:
        """A vehicle's samples between ``t0`` and ``t1`` (epoch seconds), oldest first."""
        with self._tlock:
            rows = self._tdb.execute("SELECT t, lat, lon, alt, heading, mode, armed, battery, health "
                                     "FROM telemetry WHERE vehicle = ? AND t >= ? AND t <= ? "
                                     "ORDER BY t LIMIT ?",
                                     (vehicle, t0, t1, limit)).fetchall()
        return [dict(r) | {"armed": None if r["armed"] is None else bool(r["armed"])} for r in rows]

    def prune(self, events_keep_s: float, telemetry_keep_s: float, now: float | None = None
              ) -> tuple[int, int]:
        """Retention: delete events and telemetry older than their keep times; (events, samples) deleted.
        Commands (audit), missions, tasks and assignments are never pruned."""
        now = time.time() if now is None else now
        with self.transaction("retention") as db:
            ev = db.execute("DELETE FROM events WHERE t < ?", (now - events_keep_s,)).rowcount
        with self._tlock:
            try:
                tel = self._tdb.execute("DELETE FROM telemetry WHERE t < ?",
                                        (now - telemetry_keep_s,)).rowcount
            except sqlite3.Error as exc:
                raise StorageError("retention", exc) from exc
        return int(ev), int(tel)

    # --- the vehicle registry ---------------------------------------------------------------------------
    def put_vehicle(self, vid: int, name: str, control_url: str | None) -> None:
        self._write("INSERT INTO vehicles (id, name, control_url, registered) VALUES (?,?,?,?) "
                    "ON CONFLICT(id) DO UPDATE SET name=excluded.name, control_url=excluded.control_url",
                    (vid, name, control_url, time.time()), "vehicle")

    def vehicles(self) -> list[dict[str, Any]]:
        return self._read("SELECT id, name, control_url FROM vehicles ORDER BY id")


@contextmanager
def suppress_sqlite() -> Iterator[None]:
    try:
        yield
    except sqlite3.Error:
        log.exception("database: clean-up failed")
