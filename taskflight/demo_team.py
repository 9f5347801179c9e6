"""The team demo (``scripts/demo``): three vehicles, one mission, team tasks, a report.

``taskflight demo-team [--keep]`` starts a fleet as ``taskflight up --vehicles 3`` does
(:class:`taskflight.up.Up`: the models in one process, a companion per vehicle on one team link, the
ground service), then plays a short scenario:

* vehicle 1 (system id 1) flies seed 000's scan-and-search mission (Sec. VII, Fig. 15:
  ``mission_specs/scan_and_search_outdoor.yaml``, take-off, scan-ground, fly-to, land) given to its
  companion as a directed mission (``POST /mission`` + ``/mission/start``: the process-monitor tier of
  seed 003 Fig. 1, which takes the vehicle out of the team);
* the team gets a visit and a patrol line (seed 003 Sec. II, the team-control tier) through the ground
  service's ``POST /api/tasks`` (or, with ``--no-ground``, an in-process team-control station); the
  other two vehicles divide them among themselves (Sec. III-B);
* once the mission has ended, the visit is done and the patrol has been flown for ``--patrol`` simulated
  seconds, the patrol is cancelled and a report printed: what each vehicle did, each task's state and
  holders, each vehicle's flight time and distance, and the tracking figure from its companion's flight
  log (streamed position setpoints against the autopilot's LOCAL_POSITION_NED at the same autopilot time).

``--autopilot arducopter`` flies it on ArduPilot's own copter SITL, one per vehicle
(:mod:`taskflight.arducopter_fleet`, ``$TASKFLIGHT_ARDUCOPTER``).

Exit 0 when the scenario completed; with ``--keep`` the fleet then stays up for the operator (the URL
and tokens are printed) until Ctrl-C.
"""

from __future__ import annotations

import argparse
import itertools
import logging
import math
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from mission_specs import bundled
from taskflight.team_tasking import GroundTasking, StationTasking, Tasking, TaskRow, http_json
from taskflight.up import AUTOPILOTS, Up, UpError, UpOptions, ground_available, sleep_or_stop
from taskflight_common.geo import ned_to_geodetic

MISSION = bundled("scan_and_search_outdoor.yaml")
#: the fleet's home (the bundled model's default, CMAC); vehicle i < 10 stands 5 i m east of it
HOME = (-35.363261, 149.165230, 584.0)
YAML = "application/yaml"


def geo(n: float, e: float, alt: float) -> tuple[float, float, float]:
    """(lat, lon, alt above home) of the point n m north and e m east of the fleet's home."""
    lat, lon, _ = ned_to_geodetic(HOME, n, e, 0.0)
    return (lat, lon, alt)


def add_demo_team_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--vehicles", "-n", type=int, default=3, help="vehicles (default 3; at least 3)")
    p.add_argument("--speedup", type=float, default=2.0, help="simulated seconds per wall second (default 2)")
    p.add_argument("--autopilot", choices=AUTOPILOTS, default="model",
                   help="model (default) or arducopter: ArduPilot's own copter SITL, one per vehicle "
                        "($TASKFLIGHT_ARDUCOPTER; see taskflight up --help)")
    p.add_argument("--keep", action="store_true", help="stay up for the operator after the scenario")
    p.add_argument("--no-ground", action="store_true",
                   help="no ground service: the tasks go through an in-process team-control station")
    p.add_argument("--base-instance", "-I", type=int, default=0, help="instance of vehicle 0 (default 0)")
    p.add_argument("--ground-port", type=int, default=8700, help="the ground service's port (default 8700)")
    p.add_argument("--state-dir", default=None, help="logs, tokens, database (default: a temporary folder)")
    p.add_argument("--patrol", type=float, default=40.0, metavar="S",
                   help="simulated seconds the patrol is flown before it is cancelled (default 40)")
    p.add_argument("--timeout", type=float, default=400.0, metavar="S",
                   help="give up after this many simulated seconds of scenario (default 400)")


@dataclass
class Progress:
    """What the scenario saw: task rows, who held each task, the mission's end."""

    rows: dict[int, TaskRow] = field(default_factory=dict)
    holders: dict[int, list[int]] = field(default_factory=dict)
    mission_state: str = "none"
    mission_status: dict[str, Any] = field(default_factory=dict)

    def update(self, rows: list[TaskRow]) -> list[str]:
        """Take the latest rows; lines describing what changed."""
        out = []
        for r in rows:
            old = self.rows.get(r.id)
            if old is None or (old.state, old.holder) != (r.state, r.holder):
                who = f" by vehicle {r.holder}" if r.holder is not None else ""
                out.append(f"task {r.id} {r.name or r.kind}: {r.state}{who}")
            if r.holder is not None and r.holder not in self.holders.setdefault(r.id, []):
                self.holders[r.id].append(r.holder)
            self.rows[r.id] = r
        return out


def run_demo_team(args: argparse.Namespace) -> int:
    from taskflight_common.runtime import stop_on_signals

    if args.vehicles < 3:
        print("taskflight demo-team: error: --vehicles must be at least 3", file=sys.stderr)
        return 2
    if not getattr(args, "verbose", 0):  # the scenario prints the task changes itself
        logging.getLogger("companion.team").setLevel(logging.WARNING)
    stop = stop_on_signals()
    tmp = None
    if args.state_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="taskflight-demo-")
    state = Path(args.state_dir or tmp.name)  # type: ignore[union-attr]
    ground = not args.no_ground and ground_available()
    up = Up(UpOptions(vehicles=args.vehicles, state_dir=state, speedup=args.speedup,
                      base_instance=args.base_instance, ground=ground,
                      ground_port=args.ground_port, persist=False, autopilot=args.autopilot))
    try:
        print(f"taskflight demo: starting {args.vehicles} vehicles (speedup {args.speedup:g}"
              + (", ArduCopter SITL" if args.autopilot == "arducopter" else "") + ")", flush=True)
        up.start(stop)
        print(up.summary(), flush=True)
        key = str(up.team_key_path) if up.team_key_path else None  # the fleet's team key
        tasking: Tasking = (StationTasking(up.member_url, key) if not ground
                            else GroundTasking(up.ground_url or "", up.tokens["operator"][0]))
        try:
            progress = play(up, tasking, args, stop)
        finally:
            if not args.keep:
                tasking.close()
        print(report(up, progress), flush=True)
        ok = progress.mission_state == "succeeded" and all(
            r.state in ("done", "cancelled") for r in progress.rows.values())
        if args.keep:
            print("\nthe fleet stays up for the operator (Ctrl-C stops everything):\n" + up.summary(),
                  flush=True)
            while not stop.wait(0.5):
                pass
        return 0 if ok else 1
    except UpError as exc:
        print(f"taskflight demo: error: {exc}", file=sys.stderr, flush=True)
        return exc.status
    except KeyboardInterrupt:
        print("taskflight demo: interrupted", file=sys.stderr, flush=True)
        return 130
    except (RuntimeError, OSError) as exc:
        print(f"taskflight demo: failed: {exc}", file=sys.stderr, flush=True)
        return 1
    finally:
        up.stop()
        if tmp is not None:
            tmp.cleanup()


def play(up: Up, tasking: Tasking, args: argparse.Namespace, stop: threading.Event) -> Progress:
    """The scenario (module docstring); returns what it saw. RuntimeError if it does not complete."""
    k = max(args.speedup, 0.5) if args.speedup > 0 else 5.0
    progress = Progress()
    mission = VehicleMission(up, 1)
    mission.give(MISSION)
    print(f"vehicle 1: mission {MISSION.name} accepted and started ({mission.via})", flush=True)
    visit = tasking.add("visit", [geo(-20, 25, 8)], "visit")
    patrol = tasking.add("patrol_line", [geo(0, -30, 8), geo(20, -30, 8)], "patrol")
    print(f"team: visit {visit} and patrol line {patrol} added", flush=True)
    t_end = time.monotonic() + args.timeout / k + 30.0
    patrol_since: float | None = None
    cancelled = False
    while True:
        for line in progress.update(tasking.tasks()):
            print(line, flush=True)
        status = mission.status()
        if status.get("state") != progress.mission_state:
            progress.mission_state = str(status.get("state"))
            print(f"vehicle 1: mission {progress.mission_state}"
                  + (f" ({status.get('fail_reason')})" if status.get("fail_reason") else ""), flush=True)
        progress.mission_status = status
        states = {r.id: r.state for r in progress.rows.values()}
        if patrol_since is None and all(states.get(t) == "active" for t in patrol):
            patrol_since = time.monotonic()
        mission_over = progress.mission_state in ("succeeded", "aborted", "failed")
        visit_done = all(states.get(t) == "done" for t in visit)
        if (not cancelled and patrol_since is not None and visit_done
                and time.monotonic() - patrol_since >= args.patrol / k):
            for t in patrol:
                tasking.cancel(t)
            cancelled = True
            print("team: patrol cancelled after its passes", flush=True)
        if mission_over and cancelled and all(states.get(t) == "cancelled" for t in patrol):
            return progress
        if time.monotonic() > t_end:
            raise RuntimeError(f"the scenario did not complete in {args.timeout:g} simulated s: mission "
                               f"{progress.mission_state}, tasks {states}")
        sleep_or_stop(stop, 0.5)


class VehicleMission:
    """A directed mission for one vehicle: through the ground service (``POST /api/vehicles/{id}/mission``
    and ``/start``) when it runs, else straight to the vehicle's companion (``POST /mission``,
    ``/mission/start``)."""

    def __init__(self, up: Up, sysid: int) -> None:
        self.up, self.sysid = up, sysid
        self.companion = up.vehicles[sysid - 1].control_url
        self.via = "the ground service" if up.ground_url else "its companion"

    def give(self, path: Path) -> None:
        up = self.up
        if up.ground_url:
            spec = yaml.safe_load(path.read_text("utf-8"))
            base = f"{up.ground_url}/api/vehicles/{self.sysid}"
            token = up.tokens["operator"][0]
            http_json("POST", base + "/mission", token, {"mission": spec["mission"], "tree": spec["tree"]})
            http_json("POST", base + "/start", token)
            return
        answer = http_json("POST", self.companion + "/mission", up.control_token,
                           content=path.read_text("utf-8"), content_type=YAML)
        if not answer.get("accepted"):
            raise RuntimeError(f"the mission was rejected: {answer}")
        http_json("POST", self.companion + "/mission/start", up.control_token, {})

    def status(self) -> dict[str, Any]:
        if self.up.ground_url:
            return http_json("GET", f"{self.up.ground_url}/api/vehicles/{self.sysid}/mission",
                             self.up.tokens["operator"][0])
        return http_json("GET", self.companion + "/mission", self.up.control_token)


# --- the report --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FlightFigures:
    airborne_s: float
    distance_m: float
    tracking_h_rms: float
    tracking_h_max: float
    tracking_v_rms: float
    compared: int
    #: the vertical RMS (m) of each TST node's setpoints, in flight order
    v_rms_by_node: tuple[tuple[str, float], ...] = ()
    #: the fastest descent (m/s, down positive) the reference asked for and the vehicle flew
    descent_ref: float = 0.0
    descent_flown: float = 0.0

    def tracking_text(self) -> str:
        """The report's tracking figures, the vertical one also per node, and why it is large when the
        vehicle descended slower than its reference: the autopilot's own descent limit (ArduCopter's
        WPNAV_SPEED_DN, 1.5 m/s by default; the model's too) below the platform's ``vertical_speed``, so
        the reference runs ahead and the error grows with the descent's length."""
        if not self.compared:
            return "no position setpoints streamed"
        out = (f"tracking h rms {self.tracking_h_rms:.2f} m max {self.tracking_h_max:.2f} m, v rms "
               f"{self.tracking_v_rms:.2f} m over {self.compared} setpoints")
        if len(self.v_rms_by_node) > 1:
            out += " (v rms by node: " + ", ".join(f"{n} {v:.2f}" for n, v in self.v_rms_by_node) + " m)"
        if self.descent_ref - self.descent_flown > 0.2:
            out += (f"; the reference descended at up to {self.descent_ref:.1f} m/s, the vehicle at most "
                    f"{self.descent_flown:.1f} m/s: the autopilot's descent limit (WPNAV_SPEED_DN) is below "
                    "the platform's vertical_speed, so the vehicle lags each long descent")
        return out


def flight_figures(path: Path) -> FlightFigures | None:
    """Flight time (airborne above 0.5 m, autopilot time), horizontal distance and the tracking figure
    of a companion's flight log (None if it has none); the vertical figure also per TST node, with the
    fastest descent asked and flown."""
    from companion.flightlog import FlightLogError, read_flight_log
    from companion.tracking import tracking_error

    try:
        records = read_flight_log(path)
    except (OSError, FlightLogError):
        return None
    pos = [(float(r["t"]), *map(float, r["p"])) for r in records if r["type"] == "position"]
    pos.sort()
    airborne = dist = 0.0
    for a, b in itertools.pairwise(pos):
        if -a[3] > 0.5 and -b[3] > 0.5 and b[0] - a[0] < 1.0:
            airborne += b[0] - a[0]
            dist += math.hypot(b[1] - a[1], b[2] - a[2])
    sp_records = [r for r in records if r["type"] == "setpoint" and r.get("kind") == "POSITION"]
    sps = [(float(r["t"]), tuple(map(float, r["p"]))) for r in sp_records]
    tr = tracking_error(sps, pos)  # type: ignore[arg-type]
    by_node: dict[str, list[tuple[float, tuple[float, ...]]]] = {}
    for r, sp in zip(sp_records, sps, strict=True):
        by_node.setdefault(str(r.get("node") or "-"), []).append(sp)
    per_node = tuple((n, tracking_error(s, pos).v_rms) for n, s in by_node.items())  # type: ignore[arg-type]
    asked = [float(r["v"][2]) for r in sp_records if r.get("v")]
    flown = [float(r["v"][2]) for r in records if r["type"] == "position" and r.get("v")
             and -float(r["p"][2]) > 0.5]
    return FlightFigures(airborne, dist, tr.h_rms, tr.h_max, tr.v_rms, tr.compared,
                         tuple((n, v) for n, v in per_node if not math.isnan(v)),
                         max(asked, default=0.0), max(flown, default=0.0))


def report(up: Up, progress: Progress) -> str:
    lines = ["", "=== team demo report ==="]
    held: dict[int, list[str]] = {}
    for tid, who in progress.holders.items():
        r = progress.rows[tid]
        for h in who:  # in the order they held it: the last one flew it, the others handed it on
            state = r.state if h == who[-1] else f"handed to vehicle {who[-1]}"
            held.setdefault(h, []).append(f"{r.name or r.kind} (task {tid}, {state})")
    for v in up.vehicles:
        did = []
        if v.index == 0:
            m = progress.mission_status
            did.append(f"mission {m.get('mission')}: {m.get('state')}")
        did += held.get(v.sysid, [])
        lines.append(f"vehicle {v.sysid}: " + ("; ".join(did) if did else "no task (idle)"))
        fig = flight_figures(up.opts.state_dir / "logs" / f"flight{v.sysid}.jsonl")
        if fig is not None:
            lines.append(f"  flight time {fig.airborne_s:.1f} s, {fig.distance_m:.0f} m flown; "
                         f"{fig.tracking_text()}")
    lines.append("tasks:")
    for tid, r in sorted(progress.rows.items()):
        holders = ", ".join(f"vehicle {h}" for h in progress.holders.get(tid, [])) or "nobody"
        lines.append(f"  {tid} {r.kind:<12} {r.name:<8} {r.state:<10} held by {holders}")
    return "\n".join(lines)
