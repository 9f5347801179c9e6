"""The timeline of behavior activations and process executions (seed 001 Sec. 7.1.2-7.1.3, Fig. 10).

Sec. 7.1.2 checks "that the system correctly translated the sequences of behavior activations into
consistent changes in the configuration of running processes"; Fig. 10 draws them: one row per
behavior (blue bars, from activation to termination) and one per execution process (red bars, from
start to stop), the x axis in seconds. A process kept running from one behavior into the next (the
delayed stop of Sec. 6.2.3) shows as one unbroken red bar.

The input is a flight's log, JSON lines written by the coordinator and the process manager::

    {"t": 12.30, "type": "behavior", "event": "started", "behavior": "GO_TO_POINT", "activation_id": "a7",
     "requester": "mission", "params": {...}}
    {"t": 20.10, "type": "behavior", "event": "terminated", "behavior": "GO_TO_POINT", "activation_id": "a7",
     "cause": "goal_achieved"}
    {"t": 12.30, "type": "process", "event": "start" | "stop", "process": "trajectory_planner", "by": "..."}
    {"t": 12.29, "type": "request", "event": "accepted" | "rejected", "behavior": ..., "reason": ...}

``t`` is autopilot time in seconds. Lines of another type or event are skipped and counted; a line that
is not JSON, or a known line without its fields, is an error naming the file and line.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from taskflight_common.jsonlines import json_lines

log = logging.getLogger(__name__)

#: type -> (known events, required string fields besides t/type/event)
_KINDS: dict[str, tuple[frozenset[str], tuple[str, ...]]] = {
    "behavior": (frozenset({"started", "terminated"}), ("behavior",)),
    "process": (frozenset({"start", "stop"}), ("process",)),
    "request": (frozenset({"accepted", "rejected"}), ("behavior",)),
}

BEHAVIOR_COLOR = "#1f5fbf"
PROCESS_COLOR = "#c62828"


class TimelineError(ValueError):
    """A malformed log line; the message names the file and line."""


@dataclass
class TimelineLog:
    """The events of a log (sorted by time) and how many lines were skipped."""

    events: list[dict[str, Any]]
    skipped: int = 0


@dataclass
class Interval:
    """One bar: a behavior's activation or a process's execution."""

    kind: str  # "behavior" or "process"
    name: str
    start: float
    end: float
    open: bool = False  # still running at the end of the log
    cause: str | None = None  # a behavior's termination cause
    activation_id: str | None = None
    requester: str | None = None
    by: str | None = None  # the behavior that started a process


@dataclass
class _Rows:
    names: list[tuple[str, str]] = field(default_factory=list)  # (kind, name) in order of appearance

    def add(self, kind: str, name: str) -> None:
        if (kind, name) not in self.names:
            self.names.append((kind, name))


def load_log(path: str | Path) -> TimelineLog:
    """Read a JSON-lines log; events sorted by ``t`` (stable), unknown lines counted in ``skipped``."""
    events: list[dict[str, Any]] = []
    skipped = 0
    for where, ev in json_lines(path, TimelineError):
        if not isinstance(ev, dict) or ev.get("type") not in _KINDS:
            skipped += 1
            continue
        known, required = _KINDS[ev["type"]]
        if ev.get("event") not in known:
            skipped += 1
            continue
        t = ev.get("t")
        if isinstance(t, bool) or not isinstance(t, (int, float)) or t != t:
            raise TimelineError(f"{where}: field 't' must be a number of seconds, got {t!r}")
        for name in required:
            if not isinstance(ev.get(name), str) or not ev[name]:
                raise TimelineError(f"{where}: {ev['type']} line without a '{name}' name")
        ev["t"] = float(t)
        ev["_line"] = int(where.rsplit(":", 1)[1])
        events.append(ev)
    events.sort(key=lambda e: e["t"])
    if skipped:
        log.info("%s: %d line(s) of unknown type or event skipped", path, skipped)
    return TimelineLog(events, skipped)


def read_log(path: str | Path) -> list[dict[str, Any]]:
    """The events of a log (see :func:`load_log`)."""
    return load_log(path).events


def intervals(events: Iterable[dict[str, Any]]) -> list[Interval]:
    """Behavior bars (started -> terminated) and process bars (start -> stop), in order of first start.

    Behaviors pair by ``activation_id`` (by name when there is none); a termination without a start
    draws from the log's first time; bars still open end at the log's last time (``open`` True).
    Behavior bars come first, then process bars.
    """
    evs = sorted(events, key=lambda e: float(e["t"]))
    if not evs:
        return []
    t0, t_end = float(evs[0]["t"]), float(evs[-1]["t"])
    done: list[Interval] = []
    created: dict[int, int] = {}  # id(interval) -> creation order, to break ties on start time

    def new(*args: Any, **kw: Any) -> Interval:
        iv = Interval(*args, **kw)
        created[id(iv)] = len(created)
        return iv

    open_b: dict[str, Interval] = {}
    open_p: dict[str, Interval] = {}
    for ev in evs:
        t, typ, event = float(ev["t"]), ev.get("type"), ev.get("event")
        if typ == "behavior":
            name = ev["behavior"]
            key = str(ev.get("activation_id") or name)
            if event == "started":
                if key in open_b:  # started twice without an end: close the first
                    prev = open_b.pop(key)
                    prev.end = t
                    done.append(prev)
                open_b[key] = new("behavior", name, t, t, open=True,
                                       activation_id=ev.get("activation_id"), requester=ev.get("requester"))
            elif event == "terminated":
                iv = open_b.pop(key, None) or _open_by_name(open_b, name)
                if iv is None:
                    log.warning("behavior %s terminated at %.2f s without a start", name, t)
                    iv = new("behavior", name, t0, t, activation_id=ev.get("activation_id"))
                iv.end, iv.open, iv.cause = t, False, ev.get("cause")
                done.append(iv)
        elif typ == "process":
            name = ev["process"]
            if event == "start":
                if name not in open_p:
                    open_p[name] = new("process", name, t, t, open=True, by=ev.get("by"))
            elif event == "stop":
                iv = open_p.pop(name, None)
                if iv is None:
                    log.warning("process %s stopped at %.2f s without a start", name, t)
                    iv = new("process", name, t0, t, by=ev.get("by"))
                iv.end, iv.open = t, False
                done.append(iv)
    for iv in list(open_b.values()) + list(open_p.values()):
        iv.end = t_end
        done.append(iv)
    done.sort(key=lambda iv: (iv.kind != "behavior", iv.start, created[id(iv)]))
    return done


def _open_by_name(open_b: dict[str, Interval], name: str) -> Interval | None:
    for key, iv in open_b.items():
        if iv.name == name:
            return open_b.pop(key)
    return None


def rejected_requests(events: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rejected activation requests (drawn as small markers on their behavior's row)."""
    return [e for e in events if e.get("type") == "request" and e.get("event") == "rejected"]


def plot_timeline(events: list[dict[str, Any]], out_png: str | Path, title: str | None = None) -> Path:
    """Draw Fig. 10 for ``events`` into ``out_png`` (matplotlib, no display needed); return the path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    bars = intervals(events)
    rejected = rejected_requests(events)
    rows = _Rows()
    for iv in bars:
        if iv.kind == "behavior":
            rows.add("behavior", iv.name)
    for r in rejected:
        rows.add("behavior", r["behavior"])
    for iv in bars:
        if iv.kind == "process":
            rows.add("process", iv.name)
    n = max(len(rows.names), 1)
    fig = Figure(figsize=(10.0, max(2.5, 0.9 + 0.38 * n)), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ypos = {key: n - 1 - i for i, key in enumerate(rows.names)}  # first row on top
    times = [float(e["t"]) for e in events]
    span = (max(times) - min(times)) if times else 1.0
    for iv in bars:
        y = ypos[(iv.kind, iv.name)]
        color = BEHAVIOR_COLOR if iv.kind == "behavior" else PROCESS_COLOR
        width = max(iv.end - iv.start, span * 0.002)
        ax.broken_barh([(iv.start, width)], (y - 0.3, 0.6), facecolors=color,
                       edgecolors="none", alpha=0.6 if iv.open else 1.0)
        if iv.kind == "behavior" and iv.cause:
            ax.text(iv.end, y + 0.33, iv.cause, fontsize=7, ha="right", va="bottom", color="#333333")
    if rejected:
        ax.plot([float(r["t"]) for r in rejected], [ypos[("behavior", r["behavior"])] for r in rejected],
                linestyle="none", marker="x", color="black", markersize=5, label="rejected request")
        ax.legend(loc="upper right", fontsize=7)
    ax.set_yticks([ypos[k] for k in rows.names])
    ax.set_yticklabels([name for _, name in rows.names], fontsize=8)
    for label, (kind, _) in zip(ax.get_yticklabels(), rows.names, strict=True):
        label.set_color(BEHAVIOR_COLOR if kind == "behavior" else PROCESS_COLOR)
    ax.set_ylim(-0.7, n - 0.3)
    if times:
        pad = span * 0.02 or 0.5
        ax.set_xlim(min(times) - pad, max(times) + pad)
    else:
        ax.text(0.5, 0.5, "no behavior or process events", transform=ax.transAxes, ha="center")
    ax.set_xlabel("time (s)")
    ax.grid(axis="x", linestyle=":", linewidth=0.5)
    ax.set_title(title or "Behavior activations (blue) and process executions (red)", fontsize=10)
    fig.tight_layout()
    out = Path(out_png)
    fig.savefig(out, format="png")
    return out


def run_timeline(log_path: str | Path, out_png: str | Path, title: str | None = None) -> str:
    """Read a log and draw its timeline; return a one-line summary (used by the CLI)."""
    tl = load_log(log_path)
    bars = intervals(tl.events)
    out = plot_timeline(tl.events, out_png, title)
    nb = sum(1 for iv in bars if iv.kind == "behavior")
    return (f"{out}: {nb} behavior activation(s), {len(bars) - nb} process execution(s)"
            + (f", {tl.skipped} line(s) skipped" if tl.skipped else ""))
