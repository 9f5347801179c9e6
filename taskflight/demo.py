"""``taskflight demo``: the main job on embedded defaults, the whole stack on one machine.

The bundled autopilot model runs in this process (its own thread, ``--speedup`` times real time) and
serves MAVLink on a loopback UDP port; a companion (:class:`companion.node.QuadNode`) connects to it as it
would to an ArduCopter, queues the flight commands of ``mission_specs/flight_commands_demo.yaml`` (take
off, a straight 3-D leg, a pause, back, land) and streams setpoints; progress is logged and a report
printed at the end. ``--model-only`` flies the model's own Python API through a 50 m square instead.
"""

from __future__ import annotations

import argparse
import logging
import math
import socket
import tempfile
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

    from autopilot_model.sitl import Sitl
    from companion.flight.commands import FlightCommand
    from companion.node import QuadNode

log = logging.getLogger(__name__)

DEMO_COMMANDS = Path(__file__).resolve().parents[1] / "mission_specs" / "flight_commands_demo.yaml"


def add_demo_arguments(p: argparse.ArgumentParser) -> None:
    from autopilot_model.demo import add_demo_arguments as add_model_demo_arguments

    add_model_demo_arguments(p)
    p.add_argument("--model-only", action="store_true",
                   help="fly the model's Python API through a square instead of the companion over MAVLink")
    p.add_argument("--commands", default=str(DEMO_COMMANDS),
                   help="flight-command YAML for the companion (default: mission_specs/"
                        "flight_commands_demo.yaml)")
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


def _run_stack_demo(args: argparse.Namespace) -> int:
    from autopilot_model.sitl import Sitl
    from companion.flight.codec import load_commands
    from companion.node import QuadNode
    from taskflight.yamlio import ConfigError

    speedup = args.speedup if args.speedup is not None else 5.0
    if speedup <= 0:
        log.error("the stack demo needs a finite --speedup (the companion runs on the wall clock too)")
        return 2
    try:
        commands = load_commands(args.commands)
    except (ConfigError, ValueError) as exc:
        log.error("%s", exc)
        return 2
    port = _free_udp_port()
    with tempfile.TemporaryDirectory(prefix="taskflight-demo-") as state:
        sitl = Sitl(instance=0, urls=[f"udpin:127.0.0.1:{port}"], speedup=speedup, state_dir=state,
                    airframe=args.airframe, sensors=args.sensors, use_truth=args.truth, seed=args.seed,
                    persist=False)
        stop = threading.Event()
        model = threading.Thread(target=sitl.run, args=(None, stop), name="autopilot-model", daemon=True)
        model.start()
        node = QuadNode(f"udpout:127.0.0.1:{port}", rate_hz=20.0)
        errors: list[float] = []
        world = sitl.vehicle.world

        def track(sp: object, _fields: object, _t_ap: float) -> None:
            p = getattr(sp, "p", None)
            if p is not None:
                errors.append(math.dist(p, (float(world.x[0]), float(world.x[1]), float(world.x[2]))))

        node.setpoint_listeners.append(track)
        t_wall = time.perf_counter()
        try:
            node.start()
            ok = _fly(sitl, node, commands, args.timeout, speedup)
        finally:
            node.close()
            stop.set()
            model.join(10.0)
            sitl.close()
        wall = time.perf_counter() - t_wall
    st = node.qapi_status()
    lines = [
        "",
        "Taskflight demo: autopilot model + companion over MAVLink (loopback UDP)",
        f"  flight commands: {args.commands} ({len(commands)} commands)",
        f"  simulated {sitl.vehicle.clock.now():.1f} s in {wall:.1f} s wall (model at {speedup:g}x)",
        f"  setpoints streamed: {node.streamed}; queue: {st.queue_status.name}, "
        f"command index {st.current_command_index}",
        f"  distance of the true position from the streamed setpoint: "
        f"mean {sum(errors) / max(len(errors), 1):.2f} m, max {max(errors, default=math.nan):.2f} m",
        f"  landed and disarmed: {not sitl.vehicle.nav.armed}",
        f"  result: {'OK' if ok else 'FAILED'}",
    ]
    print("\n".join(lines))  # the command's report (CLI output, not library logging)
    return 0 if ok else 1


def _fly(sitl: Sitl, node: QuadNode, commands: list[FlightCommand], timeout_s: float,
         speedup: float) -> bool:
    """Wait for the vehicle to be ready, run the commands, log progress; True once landed and done."""
    v = sitl.vehicle
    wall_deadline = time.monotonic() + timeout_s / speedup + 30.0

    def wait(pred: Callable[[], bool], what: str) -> bool:
        while time.monotonic() < wall_deadline:
            if pred():
                return True
            time.sleep(0.05)
        log.error("demo: timed out waiting for %s", what)
        return False

    log.info("demo: waiting for the companion's link and the vehicle's pre-arm checks")
    mirror = node.link.mirror

    def ready() -> bool:
        snap = mirror.snapshot()
        return snap.heartbeats > 0 and snap.gps_fix_type >= 3 and v.estimator.healthy

    if not wait(ready, "link and pre-arm checks"):
        return False
    node.add_commands(commands)
    node.run()
    last = -1
    while time.monotonic() < wall_deadline:
        st = node.qapi_status()
        if st.current_command_index != last:
            last = st.current_command_index
            n, e, d = (float(x) for x in v.world.x[:3])
            log.info("demo: command %d/%d (%s) at N %.1f E %.1f alt %.1f m", min(last + 1, len(commands)),
                     len(commands), st.current_command_status.name, n, e, -d)
        if last >= len(commands) - 1 and not v.nav.armed and v.nav.landed_state == 1:
            log.info("demo: landed and disarmed")
            return True
        if st.queue_system_status.name == "OVERRIDDEN":
            log.error("demo: the vehicle was taken over (%s)", v.nav.action)
            return False
        time.sleep(0.05)
    log.error("demo: the flight did not finish in time")
    return False
