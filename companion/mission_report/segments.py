"""Fig. 16b of seed 000 from a flight log: segments, their endpoints p0..pN, and the tracking figures.

Fig. 16b lists "the flight commands implementing the TST Executors used in the presented mission", one
row per *segment*: the executor, the segment's endpoints (p0-p1, p1-p5, ...), the H / V / Hd channel
modes, the end condition and the flags. A segment is a contiguous span of streamed setpoints of one
TST node, one channel configuration and one break-in state: consecutive waypoint commands of a scan
with the same modes are one row (the paper's "scan-ground p1-p5": four flights to waypoints), a
break-in (the operator's joystick: all channels ExtVel, E_User) is its own row labelled "(paused)", or
"(paused/enoughed)" when the operator ended it with *enough* (Sec. VII). The endpoints are where one
segment hands over to the next; p0 is where the vehicle started (on the ground, before the
autopilot's own take-off) and the last point where the log ends (after touch-down).

Decisions (documented once here)
    * Setpoints streamed while the queue holds without a command (between two nodes) belong to the
      segment before them; a span shorter than ``min_setpoints`` setpoints (a tick or two where an
      event and the command change straddle each other) is merged into its neighbour.
    * A break-in is the time between ``break_in_start`` (or ``node_paused``) and ``break_in_end`` (or
      ``node_continued`` / ``node_enoughed`` / ``node_aborted`` / ``node_finished``), and any setpoint
      of a queue pause routine (``routine_id``). It was *enoughed* when its end says
      ``outcome: enoughed`` or a ``node_enoughed`` follows within :data:`ENOUGH_WINDOW_S`.
    * Tracking (Sec. VII: "maximum absolute control error ... horizontal ... vertical (excluding
      takeoff)"): each streamed *position* setpoint against the autopilot's LOCAL_POSITION_NED at the
      setpoint's time (:func:`companion.tracking.tracking_error`); velocity-only setpoints (ExtVel
      joystick) are not position references and never count; with ``skip_takeoff`` the setpoints of
      take-off and allow-landing commands are left out of both figures (the autopilot's own take-off
      and LAND are never streamed anyway).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from companion.tracking import tracking_error

#: a node_enoughed this soon after a break-in ends makes it "(paused/enoughed)"
ENOUGH_WINDOW_S = 1.0
_BREAK_START = frozenset({"break_in_start", "node_paused"})
_BREAK_END = frozenset({"break_in_end", "node_continued", "node_enoughed", "node_aborted", "node_finished"})
#: Fig. 16b's spelling of the modes
MODE_NAMES = {"POS": "Pos", "WITH_HOR": "WithHor", "EXT_POS": "ExtPos", "EXT_VEL": "ExtVel",
              "RC_VEL": "RCVel", "DNU": "DNU", "KEEP_DISTANCE": "KeepDistance", "FLIGHT_DIR": "FlightDir",
              "POINT": "Point", "EXT_POINT": "ExtPoint"}
END_NAMES = {"e_h": "E_H", "e_v": "E_V", "e_hd": "E_Hd", "e_any": "E_Any", "e_user": "E_User"}
TABLE_COLUMNS = ("TST Executor", "Segment endpoints", "Horizontal", "Vertical", "Heading", "End condition",
                 "Flags")


@dataclass(frozen=True)
class Plan:
    """The ``plan`` event: the area (north, east), the scan waypoints (north, east, up), node types."""

    area_ne: list[tuple[float, float]]
    waypoints_neu: list[tuple[float, float, float]]
    node_types: dict[str, str]


@dataclass(frozen=True)
class BreakIn:
    t0: float
    t1: float
    node: str | None
    enoughed: bool


@dataclass
class Segment:
    """One row of Fig. 16b: setpoints ``i0..i1`` (inclusive) of the log's setpoint list."""

    node: str | None
    config: tuple[Any, ...] | None  # (h, v, hd, end flags, e_wait, take_off, allow_landing)
    break_in: bool
    i0: int
    i1: int
    t0: float
    t1: float
    command_keys: list[str] = field(default_factory=list)
    executor: str = "-"

    @property
    def count(self) -> int:
        return self.i1 - self.i0 + 1


@dataclass(frozen=True)
class Point:
    """p_index: a segment endpoint at (north, east), autopilot time t."""

    index: int
    t: float
    north: float
    east: float

    @property
    def label(self) -> str:
        return f"p{self.index}"


@dataclass(frozen=True)
class MissionTracking:
    """Sec. VII's figures in centimetres: measured position against the streamed setpoint at its time."""

    compared: int
    skipped: int  # without telemetry around them
    excluded: int  # take-off / landing / velocity-only setpoints
    h_max_cm: float
    h_rms_cm: float
    v_max_cm: float
    v_rms_cm: float

    def lines(self) -> list[str]:
        return [f"tracking: {self.compared} position setpoints vs LOCAL_POSITION_NED at their autopilot time "
                f"({self.excluded} take-off / landing / velocity-only left out, "
                f"{self.skipped} without telemetry)",
                f"  horizontal max {self.h_max_cm:.1f} cm, RMS {self.h_rms_cm:.1f} cm; "
                f"vertical (without take-off) max {self.v_max_cm:.1f} cm, RMS {self.v_rms_cm:.1f} cm"]


# --- reading the records ---------------------------------------------------------------------------
def of_type(records: list[dict[str, Any]], kind: str) -> list[dict[str, Any]]:
    return [r for r in records if r.get("type") == kind]


def events(records: list[dict[str, Any]], name: str | None = None) -> list[dict[str, Any]]:
    return [r for r in records if r.get("type") == "event" and (name is None or r.get("event") == name)]


def plan_of(records: list[dict[str, Any]]) -> Plan | None:
    """The last ``plan`` event, or None."""
    plans = events(records, "plan")
    if not plans:
        return None
    p = plans[-1]
    nodes = {str(n["id"]): str(n.get("type", n["id"])) for n in p.get("nodes") or [] if "id" in n}
    return Plan([(float(a[0]), float(a[1])) for a in p.get("area_ne") or []],
                [(float(w[0]), float(w[1]), float(w[2]) if len(w) > 2 else math.nan)
                 for w in p.get("waypoints_neu") or []], nodes)


def break_ins(records: list[dict[str, Any]]) -> list[BreakIn]:
    """Break-in intervals from the events (see the module docstring)."""
    out: list[BreakIn] = []
    evs = sorted(events(records), key=lambda r: r["t"])
    enough_times = [(r["t"], r.get("node")) for r in evs if r["event"] == "node_enoughed"]
    start: dict[str, Any] | None = None
    for r in evs:
        if r["event"] in _BREAK_START and start is None:
            start = r
        elif r["event"] in _BREAK_END and start is not None:
            node = start.get("node") or r.get("node")
            enoughed = r["event"] == "node_enoughed" or r.get("outcome") == "enoughed" or any(
                r["t"] <= t <= r["t"] + ENOUGH_WINDOW_S and (n is None or node is None or n == node)
                for t, n in enough_times)
            out.append(BreakIn(start["t"], r["t"], node, enoughed))
            start = None
    if start is not None:
        out.append(BreakIn(start["t"], math.inf, start.get("node"), False))
    return out


def _config(command: dict[str, Any] | None) -> tuple[Any, ...] | None:
    if command is None:
        return None
    return (command.get("h"), command.get("v"), command.get("hd"), tuple(command.get("end") or ()),
            command.get("e_wait"), bool(command.get("take_off")), bool(command.get("allow_landing")))


# --- segments -----------------------------------------------------------------------------------------
def segments(records: list[dict[str, Any]], min_setpoints: int = 3) -> list[Segment]:
    """The log's segments in time order (module docstring), each with its executor label."""
    sps = of_type(records, "setpoint")
    commands = {r["key"]: r for r in of_type(records, "command") if r.get("key") is not None}
    bis = break_ins(records)
    segs: list[Segment] = []
    for i, sp in enumerate(sps):
        key = sp.get("key")
        t = float(sp["t"])
        in_break = sp.get("routine_id") is not None or any(b.t0 <= t <= b.t1 for b in bis)
        if key is None and segs:  # holding between commands: part of the segment before
            _extend(segs[-1], i, t, None)
            continue
        ident = (sp.get("node"), _config(commands.get(key)) if key is not None else None, in_break)
        last = segs[-1] if segs else None
        if last is not None and (last.node, last.config, last.break_in) == ident:
            _extend(last, i, t, key)
        else:
            segs.append(Segment(ident[0], ident[1], in_break, i, i, t, t, [key] if key is not None else []))
    segs = _merge_short(segs, min_setpoints)
    node_types = (plan_of(records) or Plan([], [], {})).node_types
    for s in segs:
        s.executor = _executor(s, bis, node_types)
    return segs


def _extend(seg: Segment, i: int, t: float, key: str | None) -> None:
    seg.i1, seg.t1 = i, t
    if key is not None and key not in seg.command_keys:
        seg.command_keys.append(key)


def _merge_short(segs: list[Segment], min_setpoints: int) -> list[Segment]:
    """Fold spans shorter than ``min_setpoints`` into the segment before (the first into the next), then
    join neighbours that have become equal."""
    out: list[Segment] = []
    for s in segs:
        if out and s.count < min_setpoints:
            _absorb(out[-1], s)
        elif out and out[-1].count < min_setpoints and len(out) == 1:
            s.i0, s.t0 = out[-1].i0, out[-1].t0
            first = out[-1].command_keys
            s.command_keys = first + [k for k in s.command_keys if k not in first]
            out[-1] = s
        elif out and (out[-1].node, out[-1].config, out[-1].break_in) == (s.node, s.config, s.break_in):
            _absorb(out[-1], s)
        else:
            out.append(s)
    return out


def _absorb(into: Segment, s: Segment) -> None:
    into.i1, into.t1 = s.i1, s.t1
    into.command_keys += [k for k in s.command_keys if k not in into.command_keys]


def _executor(seg: Segment, bis: list[BreakIn], node_types: dict[str, str]) -> str:
    overlapping = [b for b in bis if b.t0 <= seg.t1 and seg.t0 <= b.t1]
    node = seg.node if seg.node is not None else next((b.node for b in overlapping if b.node), None)
    name = node_types.get(node, node) if node is not None else "-"
    if not seg.break_in:
        return name
    enoughed = any(b.enoughed for b in overlapping)
    return f"{name} (paused/enoughed)" if enoughed else f"{name} (paused)"


def points(records: list[dict[str, Any]], segs: list[Segment] | None = None) -> list[Point]:
    """p0 (where the vehicle started: the first reported position before the first setpoint), one point
    where each segment hands over to the next (the new segment's first setpoint) and the last point
    (the last reported position after the last setpoint, i.e. after touch-down)."""
    sps = of_type(records, "setpoint")
    if not sps:
        return []
    segs = segments(records) if segs is None else segs
    pos = sorted(of_type(records, "position"), key=lambda r: r["t"])
    first, last = sps[0], sps[-1]
    start = pos[0] if pos and pos[0]["t"] <= first["t"] else first
    end = pos[-1] if pos and pos[-1]["t"] >= last["t"] else last
    pts = [Point(0, float(start["t"]), start["p"][0], start["p"][1])]
    for s in segs[1:]:
        sp = sps[s.i0]
        pts.append(Point(len(pts), float(sp["t"]), sp["p"][0], sp["p"][1]))
    pts.append(Point(len(pts), float(end["t"]), end["p"][0], end["p"][1]))
    return pts


# --- the table ----------------------------------------------------------------------------------------
def fig16b_table(records: list[dict[str, Any]], min_setpoints: int = 3) -> list[dict[str, Any]]:
    """One row per segment with Fig. 16b's columns (:data:`TABLE_COLUMNS`), plus ``node``, ``t0``, ``t1``,
    ``commands`` (the command keys of the segment) and ``tracking`` (its :class:`MissionTracking`, all of
    its position setpoints)."""
    segs = segments(records, min_setpoints)
    pts = points(records, segs)
    rows: list[dict[str, Any]] = []
    for k, s in enumerate(segs):
        h, v, hd, end, e_wait, take_off, allow_landing = s.config or ("-", "-", "-", (), None, False, False)
        ends = [END_NAMES.get(e, e) for e in end]
        if e_wait is not None:
            ends.append(f"E_Wait({e_wait:g} s)")
        flags = [name for flag, name in ((take_off, "Takeoff"), (allow_landing, "Allow landing")) if flag]
        rows.append({"TST Executor": s.executor, "Segment endpoints": f"{pts[k].label}-{pts[k + 1].label}",
                     "Horizontal": MODE_NAMES.get(h, h), "Vertical": MODE_NAMES.get(v, v),
                     "Heading": MODE_NAMES.get(hd, hd), "End condition": ", ".join(ends) or "-",
                     "Flags": ", ".join(flags) or "-", "node": s.node, "t0": s.t0, "t1": s.t1,
                     "commands": list(s.command_keys),
                     "tracking": tracking(records, skip_takeoff=False, span=(s.i0, s.i1))})
    return rows


def table_markdown(rows: list[dict[str, Any]], with_tracking: bool = False) -> str:
    """Fig. 16b as a Markdown table; ``with_tracking`` adds each segment's horizontal and vertical
    tracking error, max / RMS in cm, of its position setpoints (take-off and landing included: a row
    shows what happened in it)."""
    columns = [*TABLE_COLUMNS, *(("H max / RMS (cm)", "V max / RMS (cm)") if with_tracking else ())]
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        cells = [str(r[c]) for c in TABLE_COLUMNS]
        if with_tracking:
            tr: MissionTracking = r["tracking"]
            cells += ["-" if not tr.compared else f"{tr.h_max_cm:.1f} / {tr.h_rms_cm:.1f}",
                      "-" if not tr.compared else f"{tr.v_max_cm:.1f} / {tr.v_rms_cm:.1f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


# --- tracking ------------------------------------------------------------------------------------------
def tracking(records: list[dict[str, Any]], skip_takeoff: bool = True,
             span: tuple[int, int] | None = None) -> MissionTracking:
    """Horizontal and vertical max / RMS (cm) of the measured position against the streamed position
    setpoints (module docstring), of setpoints ``span`` = (i0, i1) inclusive only if given (a segment).
    The measured positions are the ``position`` records (by ``time_boot_ms``); a log without them uses
    the setpoint records' mirrored position at ``t - m_age``."""
    commands = {r["key"]: r for r in of_type(records, "command") if r.get("key") is not None}
    compared: list[tuple[float, tuple[float, float, float]]] = []
    excluded = 0
    samples: list[tuple[float, float, float, float]] = []
    for i, sp in enumerate(of_type(records, "setpoint")):
        if sp.get("m") is not None and sp.get("m_age") is not None:
            samples.append((float(sp["t"]) - float(sp["m_age"]), *sp["m"]))
        if span is not None and not span[0] <= i <= span[1]:
            continue
        cmd = commands.get(sp.get("key")) or {}
        phase = bool(cmd.get("take_off") or cmd.get("allow_landing"))
        if sp.get("kind") != "POSITION" or (skip_takeoff and phase):
            excluded += 1
        else:
            compared.append((float(sp["t"]), tuple(sp["p"])))
    positions = [(float(r["t"]), *r["p"]) for r in of_type(records, "position")] or samples
    tr = tracking_error(compared, positions)
    return MissionTracking(tr.compared, tr.skipped, excluded, tr.h_max * 100, tr.h_rms * 100, tr.v_max * 100,
                           tr.v_rms * 100)
