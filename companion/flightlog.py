"""The companion's flight log (``--flight-log FILE``): what Fig. 16 of seed 000 is drawn from.

Seed 000 Sec. VII shows one scan-and-search flight twice: Fig. 16a the picture (the area, the scan
pattern, the position setpoints P_d, the actual path, the points p0..p12 where the executing flight
command changes) and Fig. 16b the table of segments (the TST executor, the segment endpoints, the
H / V / Hd channel modes, the end condition, the take-off / allow-landing flags); the text gives the
tracking error (horizontal and vertical, "excluding takeoff"). :class:`FlightRecorder` writes
everything those need, as JSON lines, while the companion flies; :mod:`companion.mission_report`
draws and tabulates it.

Record types (one JSON object per line; ``t`` is always autopilot time in seconds, the clock the
companion follows; positions local NED metres, angles radians)::

    {"type": "header", "t": 12.0, "format": "taskflight-flight-log", "version": 1, "rate_hz": 20.0}
    {"type": "command", "t": 14.05, "key": "c17", "command_id": 17, "routine_id": null,
     "h": "POS", "v": "WITH_HOR", "hd": "FLIGHT_DIR", "end": ["e_h"], "e_wait": null,
     "take_off": false, "allow_landing": false, "spec": {...}}          # once per command key
    {"type": "setpoint", "t": 14.10, "key": "c17", "command_id": 17, "routine_id": null,
     "node": "n3", "kind": "POSITION", "qt": 14.1, "p": [n, e, d], "v": [vn, ve, vd], "yaw": 0.0,
     "m": [n, e, d], "mv": [vn, ve, vd], "m_age": 0.03, "mode": "GUIDED", "armed": true,
     "landed": false, "extra": {...}}                                   # one per streamed setpoint
    {"type": "position", "t": 14.12, "p": [n, e, d], "v": [vn, ve, vd]}  # each LOCAL_POSITION_NED
    {"type": "event", "t": 30.5, "event": "break_in_start", "node": "n3", ...}   # mark(event, ...)

* ``command`` describes the flight command producing the setpoints: ``key`` is ``c<command_id>``
  for a queued command, ``b:<routine_id>`` for a pause routine of the queue (seed 000 Sec. V:
  e.g. ``joystick``, all channels ExtVel), whose first command is described (``n_commands`` says how
  many it has). ``end`` lists the raised flags of the end condition (Fig. 8: e_h, e_v, e_hd, e_any,
  e_user), ``e_wait`` its timeout; ``spec`` is the full command
  (:func:`companion.flight.codec.command_to_dict`).
* ``setpoint``: ``qt`` is the queue's own time of the setpoint (the generator's clock;
  :func:`streamed_setpoints` rebuilds the stream with it for the continuity check); ``key`` is null while the
  queue holds without a command; ``m`` / ``mv`` the mirrored
  LOCAL_POSITION_NED at the tick and ``m_age`` how much older than ``t`` it is (null before the
  first; slightly negative when a sample newer than the tick's scheduled time has already arrived);
  ``node`` the active TST node (the execution system's callable); ``extra`` whatever the ``extra``
  callable returned (left out when empty).
* ``position``: the autopilot's own report, stamped by its ``time_boot_ms``, also while nothing is
  streamed (the autopilot's take-off, LAND), so the actual path is complete; while the vehicle is disarmed
  (its last HEARTBEAT) and not known to be in the air (EXTENDED_SYS_STATE), one a second at most
  (``DISARMED_POSITION_EVERY_S``: it sits on the ground, and an idle fleet's companions wrote 20 records a
  second each for nothing).
* ``event``: written by :meth:`FlightRecorder.mark` for the execution system. Names used by the
  report: ``plan`` (``area_ne`` [[n, e], ...], ``waypoints_neu`` [[n, e, up], ...], ``nodes``
  [{"id", "type"}, ...]); ``node_started`` / ``node_finished`` / ``node_paused`` /
  ``node_continued`` / ``node_enoughed`` / ``node_aborted`` (``node``); ``break_in_start`` /
  ``break_in_end`` (``node``; the end with ``outcome`` continued | enoughed | aborted);
  ``detection`` (e.g. ``object``, ``position``). Other names are kept and ignored by the report.

:func:`read_flight_log` reads a log back; a line that is not a JSON object with ``type`` and a
numeric ``t`` is a :class:`FlightLogError` naming the file and line.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from taskflight_common.jsonlines import json_lines

if TYPE_CHECKING:
    from companion.flight.commands import FlightCommand
    from companion.flight.limits import Limits
    from companion.flight.setpoint import Setpoint
    from companion.flight.simulate import Violation
    from companion.link.setpoints import TargetFields
    from companion.node import QuadNode

log = logging.getLogger(__name__)

FORMAT = "taskflight-flight-log"
VERSION = 1
RECORD_TYPES = frozenset({"header", "command", "setpoint", "position", "event"})
_RESERVED = frozenset({"t", "type", "event"})


class FlightLogError(ValueError):
    """A malformed flight-log line; the message names the file and line."""


#: decimals of the log's positions, velocities and angles (0.1 mm, 0.1 mm/s, 0.1 mrad)
DECIMALS = 4
#: the longest setpoint and position records wait in memory before they are written (wall seconds)
FLUSH_EVERY_S = 0.5
#: while the vehicle is disarmed, a position record at most this often (autopilot seconds)
DISARMED_POSITION_EVERY_S = 1.0
#: the record types written in batches (the others are written at once, with those before them)
_BATCHED = frozenset({"setpoint", "position"})
#: the most that rounding to :data:`DECIMALS` can add to the horizontal norm of a difference of two logged
#: vectors (each component of each end off by half a unit: sqrt(2) * 1e-4), with a margin
ROUNDING_TOLERANCE = 1.5 * 10.0 ** -DECIMALS


def _r(x: float, nd: int = DECIMALS) -> float | None:
    """A float rounded for the log (mm and better); None for NaN / infinite."""
    x = float(x)
    return round(x, nd) if math.isfinite(x) else None


def _vec(v: Any) -> list[float | None]:
    return [_r(x) for x in v]


def describe_command(key: str, command: FlightCommand, *, command_id: int | None = None,
                     routine_id: str | None = None, n_commands: int = 1) -> dict[str, Any]:
    """The ``command`` record's fields for one flight command (seed 000 Fig. 7-8, Fig. 16b's columns)."""
    from companion.flight.codec import command_to_dict  # lazy: companion.flight loads numpy, shapely, ruckig

    end = command.end
    return {"key": key, "command_id": command_id, "routine_id": routine_id,
            "h": command.horizontal.mode.name, "v": command.vertical.mode.name,
            "hd": command.heading.mode.name,
            "end": [name for name in ("e_h", "e_v", "e_hd", "e_any", "e_user") if getattr(end, name)],
            "e_wait": end.e_wait, "take_off": command.vertical.take_off,
            "allow_landing": command.vertical.allow_landing, "n_commands": n_commands,
            "spec": command_to_dict(command)}


class FlightRecorder:
    """Writes a QuadNode's flight log (see the module docstring for the records).

    Attached to the node's ``setpoint_listeners`` (tick thread, 20-50 Hz: one snapshot of the mirror,
    one dict, one write) and to its link's ``listeners`` (receive thread: LOCAL_POSITION_NED only, with
    ``positions``). ``active_node`` returns the active TST node's id (the execution system provides
    it); ``extra`` adds fields to each setpoint record. Thread-safe (one lock). Lines reach the file
    whole, in batches: a header, command or event record at once (with what came before it), setpoint and
    position records with the first one that comes :data:`FLUSH_EVERY_S` of wall time after the last
    write, everything on :meth:`close`; a companion killed outright loses at most the records of half a
    second. (One write and flush per record, 40 a second per vehicle: bench_up's 25 idle hosted companions
    went from 123 to 115 % of a core without them, 12 from 69 to 66 %.)
    """

    def __init__(self, node: QuadNode, path: str | Path, active_node: Callable[[], str | None] = lambda: None,
                 extra: Callable[[], dict[str, Any]] | None = None, *, positions: bool = True) -> None:
        self.node = node
        self.path = Path(path)
        self.active_node = active_node
        self.extra = extra
        self.records_written = 0
        self._lock = threading.Lock()
        self._file: IO[str] | None = self.path.open("w", encoding="utf-8")
        self._pending: list[str] = []
        self._flushed = time.monotonic()
        self._described: set[str] = set()
        self._callback_failed = False
        self._disarmed_position_t: float | None = None
        self._write({"type": "header", "t": _r(node.clock.now()), "format": FORMAT, "version": VERSION,
                     "rate_hz": node.rate_hz})
        node.setpoint_listeners.append(self._on_setpoint)
        if positions:
            node.link.listeners.append(self._on_message)

    # --- writing ---------------------------------------------------------------------------------------
    def _write(self, record: dict[str, Any]) -> None:
        line = json.dumps(record, separators=(",", ":"))
        with self._lock:
            if self._file is None:
                return
            self._pending.append(line)
            self.records_written += 1
            now = time.monotonic()
            if record["type"] not in _BATCHED or now - self._flushed >= FLUSH_EVERY_S:
                self._flush_locked(now)

    def _flush_locked(self, now: float) -> None:
        if self._file is not None and self._pending:
            self._file.write("\n".join(self._pending) + "\n")
            self._file.flush()
            self._pending.clear()
        self._flushed = now

    def mark(self, event: str, **fields: Any) -> None:
        """A mission event at the autopilot's current time (e.g. ``mark("break_in_start", node="n3")``);
        ``plan`` carries the area, the scan waypoints and the nodes (module docstring)."""
        if not event or not isinstance(event, str):
            raise ValueError("mark: the event name must be a non-empty string")
        clash = _RESERVED & fields.keys()
        if clash:
            raise ValueError(f"mark: field(s) {sorted(clash)} are reserved")
        self._write({"type": "event", "t": _r(self.node.clock.now()), "event": event, **fields})

    def close(self) -> None:
        """Detach from the node and close the file (idempotent)."""
        if self._on_setpoint in self.node.setpoint_listeners:
            self.node.setpoint_listeners.remove(self._on_setpoint)
        if self._on_message in self.node.link.listeners:
            self.node.link.listeners.remove(self._on_message)
        with self._lock:
            if self._file is not None:
                self._flush_locked(time.monotonic())
                self._file.close()
                self._file = None

    def __enter__(self) -> FlightRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- listeners -----------------------------------------------------------------------------------------
    def _call(self, fn: Callable[[], Any]) -> Any:
        try:
            return fn()
        except Exception:
            if not self._callback_failed:
                self._callback_failed = True
                log.exception("flight log: a recorder callback failed (logged once)")
            return None

    def _command_key(self, sp: Setpoint) -> str | None:
        if sp.routine_id is not None:
            key = f"b:{sp.routine_id}"
            if key not in self._described:
                try:
                    routine = self.node.queue.catalog.get(sp.routine_id)
                except (KeyError, ValueError):
                    return key
                self._described.add(key)
                self._write({"type": "command", "t": _r(sp.t_s), **describe_command(
                    key, routine.commands[0], routine_id=sp.routine_id,
                    n_commands=len(routine.commands))})
            return key
        if sp.command_id is None:
            return None
        key = f"c{sp.command_id}"
        if key not in self._described:
            entry = next((e for e in self.node.queue.entries if e.id == sp.command_id), None)
            if entry is None:
                return key
            self._described.add(key)
            self._write({"type": "command", "t": _r(sp.t_s),
                         **describe_command(key, entry.command, command_id=sp.command_id)})
        return key

    def _on_setpoint(self, sp: Setpoint, _fields: TargetFields, t_ap: float) -> None:
        s = self.node.link.mirror.snapshot()
        key = self._command_key(sp)
        record: dict[str, Any] = {
            "type": "setpoint", "t": _r(t_ap), "qt": round(sp.t_s, 6), "key": key,
            "command_id": sp.command_id,
            "routine_id": sp.routine_id, "node": self._call(self.active_node), "kind": sp.kind.name,
            "p": _vec(sp.p), "v": _vec(sp.v), "yaw": _r(sp.yaw), "m": None, "mv": None, "m_age": None,
            "mode": s.mode_name, "armed": s.armed, "landed": s.landed}
        if s.position is not None:
            record["m"] = _vec(s.position)
            record["mv"] = _vec(s.velocity)
            if s.position_time_ms is not None:
                record["m_age"] = _r(t_ap - s.position_time_ms * 1e-3)
        if self.extra is not None:
            extra = self._call(self.extra)
            if extra:
                record["extra"] = extra
        self._write(record)

    def _on_message(self, msg: Any) -> None:
        if msg.get_type() != "LOCAL_POSITION_NED":
            return
        t = msg.time_boot_ms * 1e-3
        s = self.node.link.mirror.snapshot()
        if s.armed or s.landed is False:  # armed, or in the air before a HEARTBEAT says armed (5 Hz)
            self._disarmed_position_t = None
        else:
            last = self._disarmed_position_t
            if last is not None and 0.0 <= t - last < DISARMED_POSITION_EVERY_S:
                return
            self._disarmed_position_t = t
        self._write({"type": "position", "t": _r(t),
                     "p": _vec((msg.x, msg.y, msg.z)), "v": _vec((msg.vx, msg.vy, msg.vz))})


def read_flight_log(path: str | Path) -> list[dict[str, Any]]:
    """The records of a flight log, in file order. Blank lines are skipped; a line that is not a JSON
    object with a string ``type`` and a numeric ``t`` raises :class:`FlightLogError` naming file:line.
    Unknown record types are kept (a newer writer); the report ignores them."""
    records: list[dict[str, Any]] = []
    for where, record in json_lines(path, FlightLogError):
        if not isinstance(record, dict):
            raise FlightLogError(f"{where}: expected a JSON object, got {type(record).__name__}")
        if not isinstance(record.get("type"), str):
            raise FlightLogError(f"{where}: no record type ('type' missing or not a string)")
        t = record.get("t")
        if isinstance(t, bool) or not isinstance(t, int | float):
            raise FlightLogError(f"{where}: 't' (autopilot time, s) missing or not a number")
        if record["type"] == "setpoint" and not _is_vec(record.get("p")):
            raise FlightLogError(f"{where}: setpoint without a position 'p' [n, e, d]")
        if record["type"] == "position" and not _is_vec(record.get("p")):
            raise FlightLogError(f"{where}: position without 'p' [n, e, d]")
        if record["type"] == "event" and not isinstance(record.get("event"), str):
            raise FlightLogError(f"{where}: event without an 'event' name")
        records.append(record)
    return records


def _is_vec(v: Any) -> bool:
    return (isinstance(v, list) and len(v) == 3
            and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v))


#: autopilot seconds without a streamed setpoint that end a stream (the companion was not in control: an
#: override by a ground station, the autopilot's own take-off or landing)
STREAM_GAP_S = 0.5


def streamed_segments(records: list[dict[str, Any]], gap_s: float = STREAM_GAP_S) -> list[list[Setpoint]]:
    """The streamed setpoints in uninterrupted runs: a new run starts after ``gap_s`` of autopilot time
    without one (e.g. a ground station took the vehicle and gave it back: the companion's new stream
    starts from the vehicle's own state, not from its last setpoint). Check each run with
    :func:`companion.flight.simulate.step_violations`."""
    runs: list[list[Setpoint]] = []
    last_t: float | None = None
    for r in records:
        if r["type"] != "setpoint" or "qt" not in r:
            continue
        if last_t is None or float(r["t"]) - last_t > gap_s:
            runs.append([])
        last_t = float(r["t"])
        runs[-1].extend(streamed_setpoints([r]))
    return runs


def log_violations(records: list[dict[str, Any]], limits: Limits) -> list[Violation]:
    """Continuity violations (:func:`companion.flight.simulate.step_violations`) of every uninterrupted
    run of streamed setpoints of a flight log, with the log's rounding (:data:`ROUNDING_TOLERANCE`)
    allowed: the generator's guard clamps a step to exactly its bound, and a logged step may then read
    up to that much over it."""
    from companion.flight.simulate import step_violations  # lazy: as in describe_command

    out: list[Violation] = []
    for run in streamed_segments(records):
        out += step_violations(run, limits, rel_tol=1e-6, abs_tol=ROUNDING_TOLERANCE)
    return out


def streamed_setpoints(records: list[dict[str, Any]]) -> list[Setpoint]:
    """The streamed setpoints of a flight log (queue time, position, velocity, yaw, kind) as
    :class:`~companion.flight.setpoint.Setpoint` s, for :func:`companion.flight.simulate.step_violations`
    (values are rounded to 0.1 mm in the log: :func:`log_violations` allows for that)."""
    from companion.flight.setpoint import Setpoint, SetpointKind  # lazy: as in describe_command

    out = []
    for r in records:
        if r["type"] != "setpoint" or "qt" not in r:
            continue
        out.append(Setpoint(t_s=float(r["qt"]), p=tuple(r["p"]), v=tuple(r["v"]), a=(0.0, 0.0, 0.0),
                            yaw=float(r.get("yaw") or 0.0), yaw_rate=0.0, kind=SetpointKind[r["kind"]]))
    return out
