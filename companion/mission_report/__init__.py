"""Seed 000 Fig. 16 from a flight log (:mod:`companion.flightlog`): the picture, the table, the tracking.

* :func:`plot_fig16a`: the area (green), the scan pattern (dashed grey, waypoints as circles), the
  position setpoints (blue), the actual path (red), the points p0..pN labelled.
* :func:`fig16b_table` / :func:`table_markdown`: one row per segment with the executor, the endpoints,
  the H / V / Hd modes, the end condition and the flags.
* :func:`tracking`: Sec. VII's control error, horizontal and vertical (without take-off), max and RMS.
"""

from .figure import plot_fig16a
from .segments import (
    MissionTracking,
    Plan,
    Point,
    Segment,
    break_ins,
    fig16b_table,
    plan_of,
    points,
    segments,
    table_markdown,
    tracking,
)

__all__ = ["MissionTracking", "Plan", "Point", "Segment", "break_ins", "fig16b_table", "plan_of",
           "plot_fig16a", "points", "segments", "table_markdown", "tracking"]
