"""The ground database's schema, as numbered steps (``PRAGMA user_version``).

Why ``PRAGMA user_version`` steps and not Alembic: the service talks to SQLite through the standard
:mod:`sqlite3` module (no SQLAlchemy in the dependencies); SQLite keeps a 32-bit version number in the
file's header for exactly this use, readable and writable in the same transaction as the schema change.
Each step runs in one transaction with the version bump, so a database is always at a whole version: a
step that fails leaves the file at the version before it.

* version 0: a new file, or a file of the service before versions (the tables of step 1, unnumbered);
* 1: the baseline tables (meta, tasks, task_groups, assignments, missions, vehicles, audit, events);
* 2: alerts acknowledged (``events.acked_by``, ``events.acked_at``), the event time index (retention
  prunes by time) and ``telemetry``: each vehicle's position and status at about 1 Hz (the replay).

A file of a newer version than this code knows is refused (never opened and downgraded by accident).
"""

from __future__ import annotations

import sqlite3

STEPS: tuple[tuple[str, ...], ...] = (
    (  # 1: the baseline (IF NOT EXISTS: a version-0 file of the old service already has these tables)
        "CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)",
        "CREATE TABLE IF NOT EXISTS tasks (id INTEGER PRIMARY KEY, grp INTEGER NOT NULL, kind TEXT NOT NULL, "
        "state TEXT NOT NULL, holder INTEGER, cost REAL, version INTEGER NOT NULL, name TEXT NOT NULL, "
        "task TEXT NOT NULL, updated REAL NOT NULL)",
        "CREATE TABLE IF NOT EXISTS task_groups (id INTEGER PRIMARY KEY, defn TEXT NOT NULL, "
        "pieces TEXT NOT NULL, updated REAL NOT NULL)",
        "CREATE TABLE IF NOT EXISTS assignments (id INTEGER PRIMARY KEY AUTOINCREMENT, t REAL NOT NULL, "
        "task INTEGER NOT NULL, state TEXT NOT NULL, holder INTEGER)",
        "CREATE TABLE IF NOT EXISTS missions (id INTEGER PRIMARY KEY AUTOINCREMENT, t REAL NOT NULL, "
        "vehicle INTEGER NOT NULL, mission TEXT NOT NULL, status INTEGER NOT NULL, answer TEXT NOT NULL)",
        "CREATE TABLE IF NOT EXISTS vehicles (id INTEGER PRIMARY KEY, name TEXT NOT NULL, control_url TEXT, "
        "registered REAL NOT NULL)",
        "CREATE TABLE IF NOT EXISTS audit (id INTEGER PRIMARY KEY AUTOINCREMENT, t REAL NOT NULL, "
        "who TEXT NOT NULL, role TEXT NOT NULL, action TEXT NOT NULL, target TEXT NOT NULL, body TEXT, "
        "status INTEGER NOT NULL, answer TEXT NOT NULL)",
        "CREATE TABLE IF NOT EXISTS events (id INTEGER PRIMARY KEY AUTOINCREMENT, t REAL NOT NULL, "
        "kind TEXT NOT NULL, severity TEXT NOT NULL, vehicle INTEGER, task INTEGER, message TEXT NOT NULL, "
        "data TEXT NOT NULL)",
    ),
    (  # 2: acknowledgements, retention by time, telemetry
        "ALTER TABLE events ADD COLUMN acked_by TEXT",
        "ALTER TABLE events ADD COLUMN acked_at REAL",
        "CREATE INDEX IF NOT EXISTS events_t ON events (t)",
        "CREATE TABLE IF NOT EXISTS telemetry (t REAL NOT NULL, vehicle INTEGER NOT NULL, lat REAL, "
        "lon REAL, alt REAL, heading REAL, mode TEXT, armed INTEGER, battery REAL, health TEXT)",
        "CREATE INDEX IF NOT EXISTS telemetry_vt ON telemetry (vehicle, t)",
        "CREATE INDEX IF NOT EXISTS telemetry_t ON telemetry (t)",
    ),
)

#: the schema version this code writes
VERSION = len(STEPS)


def version_of(db: sqlite3.Connection) -> int:
    return int(db.execute("PRAGMA user_version").fetchone()[0])


def migrate(db: sqlite3.Connection) -> tuple[int, int]:
    """Bring ``db`` (autocommit mode) to :data:`VERSION`, one transaction per step; returns (from, to).
    ValueError for a file newer than this code."""
    start = version_of(db)
    if start > VERSION:
        raise ValueError(f"database schema version {start} is newer than this service's {VERSION}: "
                         "upgrade taskflight or give another --db")
    for n in range(start + 1, VERSION + 1):
        db.execute("BEGIN IMMEDIATE")
        try:
            for sql in STEPS[n - 1]:
                db.execute(sql)
            db.execute(f"PRAGMA user_version = {n}")
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise
    return start, VERSION
