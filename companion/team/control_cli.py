"""``taskflight team control``: a team-control station from the command line.

``taskflight team control --team URL --tasks FILE`` joins the team link as the station (seed 003 Fig. 1, the
top tier), gives the team the tasks of the file at their ``at`` times and cancels those with a
``cancel_at``, and prints each change of the assignment as it happens (task, state, holder) and the
vehicles joining or gone. A border patrol or area scan asking for more vehicles than are free is offered a
smaller N (seed 003 Sec. II); the station takes the offer unless ``--keep-n`` (the pieces then wait for
vehicles). It ends once the script has run and every task is done or cancelled (``--stay`` keeps it up),
at ``--duration`` seconds, or on Ctrl-C; the team goes on flying without it.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any


def add_control_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--team", required=True, metavar="URL",
                   help="the team link: zenoh: (a LAN), zenoh:tcp/ROUTER:7447 (through taskflight router) or "
                        "udp://239.255.70.1:14650[?iface=ADDR] (options ?loss=F&seed=S)")
    p.add_argument("--team-key", default=None, metavar="FILE",
                   help="sign and check the team link with this key file (default $TASKFLIGHT_TEAM_KEY)")
    p.add_argument("--tasks", default=None, metavar="FILE",
                   help="team task file (YAML, e.g. mission_specs/team_tasks.yaml); none: only listen")
    p.add_argument("--keep-n", action="store_true",
                   help="add divided tasks with the N asked even when fewer vehicles are free")
    p.add_argument("--stay", action="store_true", help="stay up after every task is over")
    p.add_argument("--duration", type=float, default=None, metavar="S", help="stop after S seconds")


def run_control(args: argparse.Namespace) -> int:
    # loaded when the command runs: the command line starts without shapely and the team layer
    from companion.team.auth import team_key, warn_if_unauthenticated
    from companion.team.station import TeamControlStation
    from companion.team.taskfile import load_task_file
    from companion.team.transport import open_transport
    from taskflight_common.runtime import stop_on_signals
    from taskflight_common.yamlio import ConfigError

    try:
        script = load_task_file(args.tasks) if args.tasks else None
        key = team_key(args.team_key)
        transport = open_transport(args.team, member=0, position_of=lambda m: None)
    except (ConfigError, ValueError, OSError) as exc:
        print(f"taskflight team control: error: {exc}", file=sys.stderr)
        return 2
    warn_if_unauthenticated(transport.url, key, "team-control station")
    station = TeamControlStation(transport, fence=script.fence if script else None, key=key)
    station.listeners.append(_printer())
    stop = stop_on_signals()
    pending = sorted(script.tasks, key=lambda s: s.at) if script else []
    cancels: list[tuple[float, int]] = []
    t0 = time.monotonic()
    station.start()
    print(f"team-control station on {args.team}: {len(pending)} tasks to give", flush=True)
    try:
        while not stop.wait(0.1):
            now = time.monotonic() - t0
            while pending and pending[0].at <= now:
                item = pending.pop(0)
                ids = _add(station, item.defn, args.keep_n)
                if ids and item.cancel_at is not None:
                    cancels.append((item.cancel_at, ids[0] if len(ids) == 1 else _group_of(station, ids[0])))
            for due in [c for c in cancels if c[0] <= now]:
                cancels.remove(due)
                try:
                    station.cancel(due[1])
                except ValueError as exc:  # done meanwhile
                    print(f"cancel {due[1]}: {exc}", flush=True)
            if args.duration is not None and now >= args.duration:
                break
            if not args.stay and not pending and not cancels and station.tasks() and station.all_final():
                break
    finally:
        station.close()
    _table(station)
    return 0


def _add(station: Any, defn: Any, keep_n: bool) -> tuple[int, ...]:
    try:
        result = station.add(defn, force=keep_n)
        if result.offer is not None:
            print(f"{defn.name or defn.kind}: {defn.n} vehicles asked, {result.free} free: "
                  f"taking the offer N = {result.offer}", flush=True)
            result = station.add(type(defn)(**{**defn.__dict__, "n": result.offer}), force=True)
        return result.ids
    except ValueError as exc:
        print(f"{defn.name or defn.kind}: refused: {exc}", flush=True)
        return ()


def _group_of(station: Any, task_id: int) -> int:
    view = next((v for v in station.tasks() if v.id == task_id), None)
    return view.group if view is not None and view.group else task_id


def _printer() -> Any:
    def show(entry: dict[str, Any]) -> None:
        fields = " ".join(f"{k}={v}" for k, v in entry.items() if k not in ("t", "event"))
        print(f"{entry['t']:.1f} {entry['event']} {fields}", flush=True)
    return show


def _table(station: Any) -> None:
    print(f"{'task':>6} {'kind':<13} {'state':<11} {'holder':>6} {'cost s':>7}  name")
    for v in station.tasks():
        cost = f"{v.cost:7.1f}" if v.cost is not None and v.cost == v.cost else "      -"
        print(f"{v.id:>6} {v.kind:<13} {v.state:<11} {v.holder if v.holder is not None else '-':>6} {cost}  "
              f"{v.name}")
