"""Fig. 16a of seed 000 from a flight log: "the plot of the flight path of the experimental mission".

Sec. VII: "The area to scan is denoted using a green line. The resulting scan pattern is depicted using
a dashed gray line, and the waypoints are highlighted with circles. The position setpoints (cf. P_d in
Section IV-D) are drawn using blue lines and the actual path during the flight is marked using the red
line." The points p0..pN (:func:`companion.mission_report.segments.points`) are labelled where one
segment of Fig. 16b hands over to the next. North is up, east to the right, equal axes, metres in the
local frame of the autopilot's origin. The area and the pattern come from the log's ``plan`` event; a
log without one still gets its setpoints, path and points.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

from .segments import Point, Segment, of_type, plan_of, points, segments

log = logging.getLogger(__name__)

AREA_COLOR = "#2e7d32"
PATTERN_COLOR = "#8a8a8a"
SETPOINT_COLOR = "#1f5fbf"
PATH_COLOR = "#c62828"


def measured_path(records: list[dict[str, Any]]) -> list[tuple[float, float]]:
    """(north, east) of the actual path: the ``position`` records, else the setpoints' mirrored ``m``."""
    pos = sorted(of_type(records, "position"), key=lambda r: r["t"])
    if pos:
        return [(r["p"][0], r["p"][1]) for r in pos]
    return [(r["m"][0], r["m"][1]) for r in of_type(records, "setpoint") if r.get("m") is not None]


def label_groups(pts: list[Point], extent: float,
                 share: float = 0.03) -> list[tuple[tuple[float, float], str]]:
    """Points closer than ``share`` of the plot's ``extent`` share one label ("p0, p1, p6"), so labels at
    the take-off / landing spot do not overprint each other; each group at its first point."""
    groups: list[tuple[tuple[float, float], list[str]]] = []
    for pt in pts:
        for (north, east), labels in groups:
            if math.hypot(pt.north - north, pt.east - east) <= share * extent:
                labels.append(pt.label)
                break
        else:
            groups.append(((pt.north, pt.east), [pt.label]))
    return [(where, ", ".join(labels)) for where, labels in groups]


def _extent(ax: Any) -> float:
    ax.relim()
    (x0, y0), (x1, y1) = ax.dataLim.get_points()
    return max(x1 - x0, y1 - y0, 1.0)


def plot_fig16a(records: list[dict[str, Any]], out_png: str | Path, title: str | None = None,
                segs: list[Segment] | None = None) -> Path:
    """Draw Fig. 16a into ``out_png`` (PNG); returns its path."""
    import matplotlib  # lazy: heavy, and only drawing needs it (``taskflight --help`` stays instant)

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    segs = segments(records) if segs is None else segs
    plan = plan_of(records)
    fig, ax = plt.subplots(figsize=(8, 8), dpi=110)
    try:
        if plan is not None and plan.area_ne:
            ring = [*plan.area_ne, plan.area_ne[0]]
            ax.plot([p[1] for p in ring], [p[0] for p in ring], color=AREA_COLOR, lw=2.0,
                    label="area to scan")
        if plan is not None and plan.waypoints_neu:
            wps = plan.waypoints_neu
            ax.plot([w[1] for w in wps], [w[0] for w in wps], ls="--", color=PATTERN_COLOR, lw=1.2,
                    marker="o", mfc="none", ms=7, label="scan pattern (waypoints)")
        sps = of_type(records, "setpoint")
        if sps:
            ax.plot([r["p"][1] for r in sps], [r["p"][0] for r in sps], color=SETPOINT_COLOR, lw=1.2,
                    label="position setpoints $P_d$")
        path = measured_path(records)
        if path:
            ax.plot([p[1] for p in path], [p[0] for p in path], color=PATH_COLOR, lw=1.0, alpha=0.85,
                    label="actual path")
        for (north, east), label in label_groups(points(records, segs), _extent(ax)):
            ax.plot(east, north, "k.", ms=6)
            ax.annotate(label, (east, north), textcoords="offset points", xytext=(5, 5), fontsize=9,
                        fontweight="bold")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
        ax.grid(True, lw=0.3, alpha=0.5)
        ax.set_title(title or "Position and its setpoints during the mission (seed 000 Fig. 16a)",
                     fontsize=10)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
        out = Path(out_png)
        fig.savefig(out, format="png", bbox_inches="tight")
    finally:
        plt.close(fig)
    log.info("fig. 16a written to %s", out)
    return out
