"""``taskflight mission fig16``: seed 000 Sec. VII's scan-and-search flight with two break-ins, reproduced.

The bundled model (indoor sensor profile, its own process) and a companion with its executive and
mission layers, over loopback UDP, as a user would run them. The companion delegates
``mission_specs/scan_and_search.yaml`` (Fig. 15) to the indoor platform and flies it; the operator (this
script) breaks in twice during the scan, as in Fig. 16: at the first, the joystick moves the vehicle and
*continue* resumes the scan toward the waypoint it was flying to; at the second, the joystick moves it
again and *enough* ends the scan (the rest of its waypoints are skipped) and the mission flies on to the
fly-to point and lands. Every streamed setpoint, every measured position and every mission event go to
the flight log, from which the Fig. 16a picture, the Fig. 16b table and the tracking figure are made.
"""

from __future__ import annotations

import logging
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mission_specs import bundled

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[1]
SCAN_AND_SEARCH = bundled("scan_and_search.yaml")


@dataclass
class BreakIn:
    """At scan waypoint ``at`` (1-based, the one being flown to), fly the joystick for ``seconds`` of
    autopilot time at ``velocity`` (north, east, down m/s), then ``then`` ("continue" or "enough")."""

    at: int
    velocity: tuple[float, float, float]
    seconds: float
    then: str


DEFAULT_BREAK_INS = (BreakIn(3, (0.0, -0.6, 0.0), 3.0, "continue"),
                     BreakIn(7, (0.6, 0.0, 0.0), 3.0, "enough"))


@dataclass
class Fig16Result:
    ok: bool
    out_dir: Path
    log_path: Path
    png: Path | None = None
    table_md: str = ""
    tracking: Any = None
    waypoints: int = 0
    skipped: list[int] = field(default_factory=list)
    resume_point: tuple[float, float, float] | None = None
    landing_point: tuple[float, float, float] | None = None
    problems: list[str] = field(default_factory=list)
    wall_s: float = 0.0
    sim_s: float = 0.0


def reproduce(out_dir: str | Path | None = None, speedup: float = 5.0, mission: str | Path = SCAN_AND_SEARCH,
              break_ins: tuple[BreakIn, ...] = DEFAULT_BREAK_INS, timeout_s: float = 300.0,
              node_hook: Callable[[Any], None] | None = None) -> Fig16Result:
    """Fly the reproduction; ``node_hook(node)`` is called before the node starts (tests attach taps)."""
    from argparse import Namespace

    from companion.builder import CompanionConfig, build_companion
    from companion.tst.platform import bundled_platform
    from companion.tst.spec import load_mission
    from taskflight.demo import _free_udp_port, _model_arguments, _ready
    from taskflight.sitlproc import ModelProcess

    out = Path(out_dir) if out_dir is not None else Path(tempfile.mkdtemp(prefix="taskflight-fig16-"))
    out.mkdir(parents=True, exist_ok=True)
    result = Fig16Result(False, out, out / "flight.jsonl")
    tst = load_mission(mission)
    port = _free_udp_port()
    args = Namespace(airframe=None, modules=None, sensors="indoor", truth=False, seed=1)
    t_wall = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="taskflight-fig16-model-") as state:
        model = ModelProcess(_model_arguments(args, state, port, speedup))
        model.start()
        companion = build_companion(CompanionConfig(
            f"udpout:127.0.0.1:{port}", rate_hz=20.0, behavior_log=out / "behaviors.jsonl",
            platform=bundled_platform("indoor"), flight_log=result.log_path, control_port=None))
        node, layer, missions = companion.node, companion.layer, companion.missions
        assert layer is not None and missions is not None
        if node_hook is not None:
            node_hook(node)
        try:
            companion.start()
            wall = _WallDeadline(timeout_s / speedup + 60.0, model)
            wall.wait(lambda: _ready(node.link.mirror.snapshot()) and node.clock.synced
                      and node.link.mirror.snapshot().home is not None
                      and layer.coordinator.is_active("SELF_LOCALIZE"), "the vehicle ready")
            delegation = missions.submit(tst)
            if not delegation.accepted:
                result.problems = [f"rejected: {r}" for r in delegation.reasons]
                return result
            scan = next(p for p in delegation.plans.values() if p.task == "scan-ground")
            result.waypoints = len(scan.waypoints_neu)
            missions.start("joystick")
            _operator(node, missions, scan.node_id, break_ins, wall, result)
            wall.wait(lambda: not missions.execution.running, "the mission's end")
            wall.wait(lambda: not node.link.mirror.snapshot().armed, "landed and disarmed")
            state_now = missions.status()
            if state_now["state"] != "succeeded":
                result.problems.append(f"mission {state_now['state']}: {state_now.get('fail_reason')}")
            p = node.link.mirror.snapshot().position
            result.landing_point = (p[0], p[1], -p[2]) if p is not None else None
            result.sim_s = node.clock.now()
        except (TimeoutError, RuntimeError) as exc:
            result.problems.append(str(exc))
        finally:
            companion.close()
            model.stop()
    result.wall_s = time.perf_counter() - t_wall
    _report(result)
    result.ok = not result.problems
    return result


class _WallDeadline:
    def __init__(self, seconds: float, model: Any) -> None:
        self.deadline = time.monotonic() + seconds
        self.model = model

    def wait(self, pred: Callable[[], bool], what: str) -> None:
        while not pred():
            if not self.model.running:
                raise RuntimeError(f"the autopilot model exited while waiting for {what}")
            if time.monotonic() > self.deadline:
                raise TimeoutError(f"gave up waiting for {what}")
            time.sleep(0.01)


def _at_waypoint(missions: Any, scan_id: str, at: int) -> Callable[[], bool]:
    """True once the scan reached waypoint ``at`` or the mission ended."""
    return lambda: _scan_waypoint(missions, scan_id) >= at or not missions.execution.running


def _at_time(node: Any, t: float) -> Callable[[], bool]:
    """True once the autopilot's clock reached ``t``."""
    return lambda: bool(node.clock.now() >= t)


def _scan_waypoint(missions: Any, scan_id: str) -> int:
    run = missions.execution.runs.get(scan_id)
    return int(run.progress().get("waypoint", 0)) if run is not None and not run.finished else 0


def _operator(node: Any, missions: Any, scan_id: str, break_ins: tuple[BreakIn, ...], wall: _WallDeadline,
              result: Fig16Result) -> None:
    """The scripted operator: each break-in at its waypoint, the joystick, then continue or enough."""
    for b in break_ins:
        wall.wait(_at_waypoint(missions, scan_id, b.at), f"scan waypoint {b.at}")
        if not missions.execution.running:
            result.problems.append(f"the mission ended before the break-in at waypoint {b.at}")
            return
        missions.pause("joystick")
        log.info("fig16: break-in at scan waypoint %d", b.at)
        end = node.clock.now() + b.seconds
        while node.clock.now() < end:  # the operator's stick at 10 Hz of autopilot time
            node.push_external("ext_vel", (*b.velocity, 0.0), 0.5)
            t = node.clock.now() + 0.1
            wall.wait(_at_time(node, t), "the joystick's next sample")
        node.push_external("ext_vel", (0.0, 0.0, 0.0, 0.0), 0.5)
        if b.then == "continue":
            missions.continue_()
            p = node.link.mirror.snapshot().position
            result.resume_point = (p[0], p[1], -p[2]) if p is not None else None
        else:
            missions.enough()
            run = missions.execution.runs.get(scan_id)
            result.skipped = list(getattr(run, "skipped", []))


def _report(result: Fig16Result) -> None:
    from companion.flightlog import read_flight_log
    from companion.mission_report import fig16b_table, plot_fig16a, table_markdown, tracking

    if not result.log_path.exists():
        return
    records = read_flight_log(result.log_path)
    result.png = plot_fig16a(records, result.out_dir / "fig16a.png",
                             title="Scan-and-search with two break-ins (seed 000 Fig. 16a, reproduced)")
    result.table_md = table_markdown(fig16b_table(records))
    (result.out_dir / "fig16b.md").write_text(result.table_md + "\n", encoding="utf-8")
    result.tracking = tracking(records, skip_takeoff=True)


def report_lines(result: Fig16Result) -> list[str]:
    t = result.tracking
    verdict = "OK" if result.ok else "FAILED"
    lines = [f"fig16: {verdict}; simulated {result.sim_s:.1f} s in {result.wall_s:.1f} s wall",
             f"  scan waypoints {result.waypoints}, skipped after enough: {result.skipped}",
             f"  flight log {result.log_path}", f"  picture {result.png}", "", result.table_md, ""]
    if t is not None:
        lines += [f"  {line}" for line in t.lines()]
    lines += [f"  problem: {p}" for p in result.problems]
    return lines



def add_fig16_arguments(msub: Any) -> None:
    """``taskflight mission fig16 [--out DIR] [--speedup K]``."""
    p = msub.add_parser("fig16", help="reproduce seed 000 Fig. 16 on the bundled model (indoor sensors)")
    p.add_argument("--out", default="fig16", metavar="DIR", help="where the log, PNG and table go")
    p.add_argument("--speedup", type=float, default=5.0, help="the model's speed-up (default 5)")
    p.add_argument("--mission", default=str(SCAN_AND_SEARCH), metavar="YAML", help="the mission flown")
    p.set_defaults(mission_handler=_run_fig16)


def _run_fig16(args: Any) -> int:
    result = reproduce(args.out, args.speedup, args.mission)
    print("\n".join(report_lines(result)))  # the command's report (CLI output)
    return 0 if result.ok else 1
