"""``taskflight mission plot LOG --out PNG [--table MD]``: Fig. 16a and 16b of seed 000 from a flight log.

Prints the Fig. 16b table (Markdown) and the tracking figures of Sec. VII; writes the PNG (and the table
to ``--table``). matplotlib is imported only when drawing (:func:`~.figure.plot_fig16a`) and the flight
layer only when a log is checked (:mod:`companion.flightlog`), so ``taskflight --help`` stays instant.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from companion.flightlog import FlightLogError, read_flight_log

from .figure import plot_fig16a
from .segments import fig16b_table, segments, table_markdown, tracking


def add_mission_plot_arguments(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``plot`` to the ``taskflight mission`` sub-command group (``subparsers`` is the group's
    ``add_subparsers()`` result); it sets ``mission_handler``."""
    p = subparsers.add_parser("plot", help="draw a flight log as seed 000 Fig. 16a (PNG), tabulate Fig. 16b")
    p.add_argument("log", metavar="LOG", help="the companion's flight log (JSON lines, --flight-log)")
    p.add_argument("--out", required=True, metavar="FILE.png", help="the PNG to write (Fig. 16a)")
    p.add_argument("--table", default=None, metavar="FILE.md", help="also write Fig. 16b (Markdown)")
    p.add_argument("--title", default=None, help="the figure's title")
    p.add_argument("--with-takeoff", action="store_true",
                   help="count the take-off and landing setpoints in the tracking figures too")
    p.add_argument("--segment-tracking", action="store_true",
                   help="add each segment's tracking error (max / RMS, cm) to the table")
    p.set_defaults(mission_handler=run_mission_plot)
    return p


def run_mission_plot(args: argparse.Namespace) -> int:
    """The command: 0 when drawn, 2 for an unreadable or malformed log (the error names file:line)."""
    try:
        records = read_flight_log(args.log)
    except (OSError, FlightLogError) as exc:
        print(f"taskflight mission plot: error: {exc}", file=sys.stderr)
        return 2
    if not any(r["type"] == "setpoint" for r in records):
        print(f"taskflight mission plot: error: {args.log}: no setpoint records", file=sys.stderr)
        return 2
    try:
        png = plot_fig16a(records, args.out, args.title, segments(records))
    except OSError as exc:
        print(f"taskflight mission plot: error: {exc}", file=sys.stderr)
        return 2
    table = table_markdown(fig16b_table(records), with_tracking=args.segment_tracking)
    if args.table:
        Path(args.table).write_text(table, encoding="utf-8")
    tr = tracking(records, skip_takeoff=not args.with_takeoff)
    print("\n".join([f"fig. 16a: {png}", "", table, *tr.lines()]))  # the command's report
    return 0
