"""``taskflight demo``: the main job on embedded defaults, the whole stack on one machine.

The bundled autopilot model runs in a child process (``python -m autopilot_model.sitl``, ``--speedup``
times real time; :class:`taskflight.sitlproc.ModelProcess`), as a flight controller is a computer of its
own, and serves MAVLink on a loopback UDP port; a companion (:class:`companion.node.QuadNode`) connects to
it as it would to an ArduCopter, queues the flight commands of ``mission_specs/flight_commands_demo.yaml``
(take off, a straight 3-D leg, a pause, back, land) and streams setpoints; progress is logged and a
report printed at the end. Everything the demo knows of the vehicle comes over MAVLink, through the
companion (its mirror of the autopilot's telemetry, its estimate of the autopilot clock).
``--behaviors`` flies by behavior activation requests instead (seed 001: the companion's executive
layer, ``mission_specs/behaviors_demo.txt``; :mod:`taskflight.demo_behaviors`), ``--timeline PNG``
drawing its Fig. 10; ``--model-only`` flies the model's own Python API through a 50 m square.

The report's tracking figure (:mod:`companion.tracking`) compares what the companion streamed with what
the autopilot said the vehicle did, on one clock and in one frame: each streamed position setpoint
(SET_POSITION_TARGET_LOCAL_NED, stamped with the autopilot time of its tick) against the autopilot's
LOCAL_POSITION_NED interpolated to that time by ``time_boot_ms``. Only streamed setpoints count: the
autopilot's own take-off (MAV_CMD_NAV_TAKEOFF, nothing streamed) and the landing in LAND mode are not
part of it. It includes the real lag/lead of the vehicle behind the reference *and* the companion's
timing (its estimate of the autopilot clock, late ticks), which the report quantifies beside it (the
stream's rate and its longest gap, in autopilot time). With the model in its own process it is
decimetres at 5-10x too; a companion that ticks late (a starved CPU) lets the queue's reference fall
behind the autopilot's advancing target, and the figure then grows, honestly, with the late ticks beside it.
"""

from __future__ import annotations

import argparse
import logging
import math
import signal
import socket
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from companion.tracking import StreamRecorder
from mission_specs import bundled

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from companion.flight.commands import FlightCommand
    from companion.link.mirror import MirrorState
    from companion.node import QuadNode

log = logging.getLogger(__name__)

DEMO_COMMANDS = bundled("flight_commands_demo.yaml")
def add_demo_arguments(p: argparse.ArgumentParser) -> None:
    from autopilot_model.demo import add_demo_arguments as add_model_demo_arguments

    add_model_demo_arguments(p)
    p.add_argument("--model-only", action="store_true",
                   help="fly the model's Python API through a square instead of the companion over MAVLink")
    p.add_argument("--commands", default=str(DEMO_COMMANDS),
                   help="flight-command YAML for the companion (default: mission_specs/"
                        "flight_commands_demo.yaml)")
    p.add_argument("--behaviors", nargs="?", const="default", default=None, metavar="FILE",
                   help="fly by behavior activation requests (seed 001) instead of flight commands: one "
                        "activation per line (default: mission_specs/behaviors_demo.txt)")
    p.add_argument("--timeline", default=None, metavar="PNG",
                   help="with --behaviors: draw the behavior and process timeline (seed 001 Fig. 10)")
    p.add_argument("--timeout", type=float, default=300.0, help="give up after this many simulated seconds")


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run_demo(args: argparse.Namespace) -> int:
    if args.model_only:
        from autopilot_model.demo import run_demo as run_model_demo

        return run_model_demo(args)
    return _run_stack_demo(args)


def _model_arguments(args: argparse.Namespace, state_dir: str, port: int, speedup: float) -> list[str]:
    """``python -m autopilot_model.sitl`` options for the demo's vehicle: a throw-away state directory, the
    demo's model options, MAVLink on ``udpin:127.0.0.1:PORT`` only."""
    argv = ["--state-dir", state_dir, "--speedup", repr(speedup), "--mavlink", f"udpin:127.0.0.1:{port}",
            "--no-persist", "--seed", str(args.seed)]
    for option, value in (("--airframe", args.airframe), ("--modules", getattr(args, "modules", None)),
                          ("--sensors", args.sensors)):
        if value is not None:
            argv += [option, str(value)]
    if args.truth:
        argv.append("--truth")
    if log.isEnabledFor(logging.DEBUG):
        argv.append("-v")  # the model's INFO lines too (into this log at debug level)
    return argv


@contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt (as Ctrl-C does) for the block, so that the model process is
    stopped on the way out; only from the main thread (where signal handlers can be installed)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(*_: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run_stack_demo(args: argparse.Namespace) -> int:
    from companion.behaviors.catalog import load_catalog as load_behavior_catalog
    from companion.builder import CompanionConfig, build_companion
    from companion.flight.codec import load_commands
    from taskflight.demo_behaviors import BEHAVIORS_DEMO, fly_behaviors, load_activations
    from taskflight.sitlproc import ModelProcess
    from taskflight_common.yamlio import ConfigError

    speedup = args.speedup if args.speedup is not None else 5.0
    if speedup <= 0:
        log.error("the stack demo needs a finite --speedup (the companion runs on the wall clock too)")
        return 2
    behaviors = getattr(args, "behaviors", None)
    mission = str(BEHAVIORS_DEMO) if behaviors == "default" else behaviors
    try:
        if mission is not None:
            catalog = load_behavior_catalog()
            from companion.behaviors.activation import check_format

            texts = load_activations(mission, lambda req: check_format(catalog, req))
            commands = []
        else:
            commands = load_commands(args.commands)
    except (ConfigError, ValueError, OSError) as exc:
        log.error("%s", exc)
        return 2
    port = _free_udp_port()
    behavior_lines: list[str] = []
    with _sigterm_as_interrupt(), tempfile.TemporaryDirectory(prefix="taskflight-demo-") as state:
        model = ModelProcess(_model_arguments(args, state, port, speedup))
        try:
            model.start()
        except RuntimeError as exc:
            log.error("demo: the autopilot model did not start: %s", exc)
            return 2
        try:
            log.info("demo: autopilot model running (pid %s): %s", model.pid, model.ready_line)
            companion = build_companion(CompanionConfig(
                f"udpout:127.0.0.1:{port}", rate_hz=20.0, behaviors=mission is not None,
                behavior_catalog=catalog if mission is not None else None,
                behavior_log=Path(state) / "behaviors.jsonl" if mission is not None else None,
                missions=False, control_port=None))
            node, layer = companion.node, companion.layer
            recorder = StreamRecorder(node)
            t_wall = time.perf_counter()
            try:
                companion.start()
                if layer is not None:
                    deadline = time.monotonic() + args.timeout / speedup + 30
                    ok, behavior_lines = fly_behaviors(layer, texts, deadline, lambda: not model.running)
                    ok = ok and _wait_landed(node, time.monotonic() + 60 / speedup + 10)
                    if args.timeline and layer.log.path is not None:
                        from companion.behaviors.timeline import run_timeline

                        behavior_lines.append(f"  timeline: {run_timeline(layer.log.path, args.timeline)}")
                else:
                    ok = _fly(node, commands, args.timeout, speedup, lambda: model.running)
            finally:
                companion.close()
            wall = time.perf_counter() - t_wall
        finally:
            model.stop()  # also on Ctrl-C / SIGTERM (KeyboardInterrupt) and errors
    if model.returncode not in (0, None):
        log.warning("demo: the autopilot model exited with status %s", model.returncode)
    st = node.qapi_status()
    snap = node.link.mirror.snapshot()
    what = (f"  behavior activations: {mission} ({len(texts)} behaviors)"
            if mission is not None else f"  flight commands: {args.commands} ({len(commands)} commands)")
    lines = [
        "",
        "Taskflight demo: autopilot model (its own process) + companion over MAVLink (loopback UDP)",
        what,
        *behavior_lines,
        f"  simulated {node.clock.now():.1f} s in {wall:.1f} s wall (model at {speedup:g}x)",
        f"  setpoints streamed: {node.streamed}; queue: {st.queue_status.name}, "
        f"command index {st.current_command_index}",
        *recorder.report_lines(),
        f"  landed and disarmed: {_landed_and_disarmed(snap)}",
        f"  result: {'OK' if ok else 'FAILED'}",
    ]
    print("\n".join(lines))  # the command's report (CLI output, not library logging)
    return 0 if ok else 1


def _wait_landed(node: QuadNode, deadline_wall: float) -> bool:
    while time.monotonic() < deadline_wall:
        if _landed_and_disarmed(node.link.mirror.snapshot()):
            return True
        time.sleep(0.05)
    log.error("demo: not landed and disarmed in time")
    return False


def _landed_and_disarmed(snap: MirrorState) -> bool:
    """As the autopilot reports it: HEARTBEAT not armed, EXTENDED_SYS_STATE on the ground."""
    return not snap.armed and snap.landed is True


def _ready(snap: MirrorState) -> bool:
    """The vehicle as the companion sees it is ready to fly: heard, a 3-D GPS fix, a local position, and
    the autopilot's estimator up (HEARTBEAT system_status past BOOT/CALIBRATING, as ArduCopter's pre-arm)."""
    from pymavlink.dialects.v20 import ardupilotmega as m

    return (snap.heartbeats > 0 and snap.gps_fix_type >= 3 and snap.position is not None
            and snap.system_status not in (m.MAV_STATE_UNINIT, m.MAV_STATE_BOOT, m.MAV_STATE_CALIBRATING))


def _fly(node: QuadNode, commands: list[FlightCommand], timeout_s: float, speedup: float,
         model_running: Callable[[], bool] = lambda: True) -> bool:
    """Wait for the vehicle to be ready, run the commands, log progress; True once landed and done.

    What it knows of the vehicle is the companion's mirror of the autopilot's MAVLink telemetry;
    ``model_running`` False (the model's process has exited) ends the flight at once."""
    mirror = node.link.mirror
    wall_deadline = time.monotonic() + timeout_s / speedup + 30.0

    def model_gone() -> bool:
        if model_running():
            return False
        log.error("demo: the autopilot model has exited")
        return True

    def wait(pred: Callable[[], bool], what: str) -> bool:
        while time.monotonic() < wall_deadline and not model_gone():
            if pred():
                return True
            time.sleep(0.05)
        log.error("demo: gave up waiting for %s", what)
        return False

    log.info("demo: waiting for the companion's link and clock and the vehicle's pre-arm checks")

    def ready() -> bool:
        return _ready(mirror.snapshot()) and node.clock.synced

    if not wait(ready, "link, clock and pre-arm checks"):
        return False
    log.info("demo: ready; the companion's estimate of the autopilot clock runs at %.3fx", node.clock.rate)
    node.add_commands(commands)
    node.run()
    last = -1
    while time.monotonic() < wall_deadline:
        st = node.qapi_status()
        snap = mirror.snapshot()
        if st.current_command_index != last:
            last = st.current_command_index
            n, e, d = snap.position if snap.position is not None else (math.nan,) * 3
            log.info("demo: command %d/%d (%s) at N %.1f E %.1f alt %.1f m", min(last + 1, len(commands)),
                     len(commands), st.current_command_status.name, n, e, -d)
        if last >= len(commands) - 1 and _landed_and_disarmed(snap):
            log.info("demo: landed and disarmed")
            return True
        if st.queue_system_status.name == "OVERRIDDEN":
            log.error("demo: the vehicle was taken over (mode %s)", snap.mode_name)
            return False
        if model_gone():
            return False
        time.sleep(0.05)
    log.error("demo: the flight did not finish in time")
    return False
