"""``taskflight demo``: the main job on embedded defaults, the whole stack on one machine.

The bundled autopilot model runs in a child process (``python -m autopilot_model.sitl``, ``--speedup``
times real time; :class:`taskflight.sitlproc.ModelProcess`), as a flight controller is a computer of its
own, and serves MAVLink on a loopback UDP port; a companion (:class:`companion.node.QuadNode`) connects to
it as it would to an ArduCopter, queues the flight commands of ``mission_specs/flight_commands_demo.yaml``
(take off, a straight 3-D leg, a pause, back, land) and streams setpoints; progress is logged and a
report printed at the end. Everything the demo knows of the vehicle comes over MAVLink, through the
companion (its mirror of the autopilot's telemetry, its estimate of the autopilot clock).
``--model-only`` flies the model's own Python API through a 50 m square instead.

The report's tracking figure (:func:`tracking_error`) compares what the companion streamed with what
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
import statistics
import tempfile
import threading
import time
from bisect import bisect_left
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Iterator, Sequence

    from companion.flight.commands import FlightCommand
    from companion.flight.setpoint import Setpoint
    from companion.link.mirror import MirrorState
    from companion.link.setpoints import TargetFields
    from companion.node import QuadNode

log = logging.getLogger(__name__)

DEMO_COMMANDS = Path(__file__).resolve().parents[1] / "mission_specs" / "flight_commands_demo.yaml"
#: Telemetry samples further apart than this (autopilot seconds) are not interpolated between.
MAX_SAMPLE_GAP_S = 0.5
#: A gap between streamed setpoints longer than this (autopilot seconds) is a late tick: the companion's
#: queue advances its reference by at most 0.25 s per tick, while the autopilot moves its target on.
LATE_TICK_S = 0.25
#: Wall seconds the companion's estimate of the autopilot clock gets before the flight starts: more than
#: its rate window (:class:`companion.link.clock.AutopilotClock`, 2 s), so the first samples are out of it.
#: The model stalls on first contact (~0.15 s wall) and then catches up in a burst; with those samples in
#: the window the rate is overestimated and the setpoint stamps run up to 0.25 s ahead of the autopilot.
CLOCK_SETTLE_S = 2.5

Vec3 = tuple[float, float, float]
#: (autopilot time s, north, east, down) of one LOCAL_POSITION_NED
PositionSample = tuple[float, float, float, float]


# --- the tracking figure -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Tracking:
    """Streamed position setpoints against the autopilot-reported position at the same autopilot time."""

    compared: int
    skipped: int  # setpoints without telemetry on both sides of their time
    h_rms: float
    h_max: float
    v_rms: float
    v_max: float


def position_at(samples: Sequence[PositionSample], times: Sequence[float], t_s: float,
                max_gap_s: float = MAX_SAMPLE_GAP_S) -> Vec3 | None:
    """The position at ``t_s``, linear between the two samples around it (``times`` are the samples'
    sorted times); None outside the samples or across a gap longer than ``max_gap_s``."""
    i = bisect_left(times, t_s)
    if i < len(times) and times[i] == t_s:
        return samples[i][1:]
    if i == 0 or i == len(times):
        return None
    a, b = samples[i - 1], samples[i]
    if b[0] - a[0] > max_gap_s:
        return None
    w = (t_s - a[0]) / (b[0] - a[0])
    return (a[1] + w * (b[1] - a[1]), a[2] + w * (b[2] - a[2]), a[3] + w * (b[3] - a[3]))


def tracking_error(setpoints: Iterable[tuple[float, Vec3]], positions: Iterable[PositionSample],
                   max_gap_s: float = MAX_SAMPLE_GAP_S) -> Tracking:
    """Horizontal and vertical distance (m) of each setpoint ``(t_s, (n, e, d))`` from the reported
    position interpolated to ``t_s``; positions are ``(t_s, n, e, d)`` in the same frame, any order."""
    by_time = {s[0]: s for s in positions}  # a repeated time_boot_ms: the last one
    samples = [by_time[t] for t in sorted(by_time)]
    times = [s[0] for s in samples]
    h: list[float] = []
    v: list[float] = []
    skipped = 0
    for t_s, p in setpoints:
        q = position_at(samples, times, t_s, max_gap_s)
        if q is None:
            skipped += 1
            continue
        h.append(math.hypot(p[0] - q[0], p[1] - q[1]))
        v.append(abs(p[2] - q[2]))

    def rms(xs: list[float]) -> float:
        return math.sqrt(sum(x * x for x in xs) / len(xs)) if xs else math.nan

    return Tracking(len(h), skipped, rms(h), max(h, default=math.nan), rms(v), max(v, default=math.nan))


class StreamRecorder:
    """Records, from a :class:`~companion.node.QuadNode`'s own threads, what the tracking figure needs:
    the streamed position setpoints with their autopilot times (tick thread) and the autopilot's
    LOCAL_POSITION_NED by ``time_boot_ms`` (receive thread); also, for the companion's timing, how far
    each setpoint's stamp is ahead of the newest autopilot time received (``leads``)."""

    def __init__(self, node: QuadNode) -> None:
        from companion.link.setpoints import IGNORE_POS

        self._ignore_pos = IGNORE_POS
        self.setpoints: list[tuple[float, Vec3]] = []  # (autopilot time, position) of position setpoints
        self.stamps: list[float] = []  # autopilot time of every streamed setpoint
        self.leads: list[float] = []  # stamp minus the newest autopilot time received (the extrapolation)
        self.positions: list[PositionSample] = []
        self._clock = node.clock
        node.setpoint_listeners.append(self._on_setpoint)
        node.link.listeners.append(self._on_message)

    def _on_setpoint(self, _sp: Setpoint, fields: TargetFields, t_ap: float) -> None:
        self.stamps.append(t_ap)
        self.leads.append(t_ap - self._clock.last_sample_s)
        if not fields.type_mask & self._ignore_pos:
            self.setpoints.append((t_ap, fields.p))

    def _on_message(self, msg: Any) -> None:
        if msg.get_type() == "LOCAL_POSITION_NED":
            self.positions.append((msg.time_boot_ms * 1e-3, msg.x, msg.y, msg.z))

    def tracking(self) -> Tracking:
        return tracking_error(self.setpoints, self.positions)

    def report_lines(self) -> list[str]:
        """The report's tracking lines: what is compared, the figures, what they include."""
        tr = self.tracking()
        skipped = f" ({tr.skipped} more without telemetry around them)" if tr.skipped else ""
        gaps = [b - a for a, b in zip(self.stamps, self.stamps[1:], strict=False)]
        span = self.stamps[-1] - self.stamps[0] if self.stamps else 0.0
        rate = f"{len(gaps) / span:.1f} Hz" if span > 0 else "-"
        lines = [
            f"  tracking: {tr.compared} streamed position setpoints{skipped} vs the position the autopilot "
            "reported",
            "    (LOCAL_POSITION_NED, same local NED frame) at each setpoint's autopilot time (interpolated",
            "    by time_boot_ms), only while streaming (not the autopilot's own take-off or LAND):",
            f"    horizontal RMS {tr.h_rms:.2f} m, max {tr.h_max:.2f} m; "
            f"vertical RMS {tr.v_rms:.2f} m, max {tr.v_max:.2f} m",
            "    = the vehicle's lag/lead on the reference + the companion's timing (late/early setpoints):",
            f"    setpoints at {rate} of autopilot time over {span:.1f} s, longest gap "
            f"{max(gaps, default=0.0):.2f} s ({sum(g > LATE_TICK_S for g in gaps)} over {LATE_TICK_S:g} s)",
        ]
        if self.leads:
            lead = statistics.median(self.leads)
            lines.append(f"    setpoint stamps ahead of the newest autopilot time: median {lead:+.2f} s,"
                         f" range {min(self.leads):+.2f}..{max(self.leads):+.2f} s")
        return lines


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
    from companion.flight.codec import load_commands
    from companion.node import QuadNode
    from taskflight.sitlproc import ModelProcess
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
    with _sigterm_as_interrupt(), tempfile.TemporaryDirectory(prefix="taskflight-demo-") as state:
        model = ModelProcess(_model_arguments(args, state, port, speedup))
        try:
            model.start()
        except RuntimeError as exc:
            log.error("demo: the autopilot model did not start: %s", exc)
            return 2
        try:
            log.info("demo: autopilot model running (pid %s): %s", model.pid, model.ready_line)
            node = QuadNode(f"udpout:127.0.0.1:{port}", rate_hz=20.0)
            recorder = StreamRecorder(node)
            t_wall = time.perf_counter()
            try:
                node.start()
                ok = _fly(node, commands, args.timeout, speedup, lambda: model.running)
            finally:
                node.close()
            wall = time.perf_counter() - t_wall
        finally:
            model.stop()  # also on Ctrl-C / SIGTERM (KeyboardInterrupt) and errors
    if model.returncode not in (0, None):
        log.warning("demo: the autopilot model exited with status %s", model.returncode)
    st = node.qapi_status()
    snap = node.link.mirror.snapshot()
    lines = [
        "",
        "Taskflight demo: autopilot model (its own process) + companion over MAVLink (loopback UDP)",
        f"  flight commands: {args.commands} ({len(commands)} commands)",
        f"  simulated {node.clock.now():.1f} s in {wall:.1f} s wall (model at {speedup:g}x)",
        f"  setpoints streamed: {node.streamed}; queue: {st.queue_status.name}, "
        f"command index {st.current_command_index}",
        *recorder.report_lines(),
        f"  landed and disarmed: {_landed_and_disarmed(snap)}",
        f"  result: {'OK' if ok else 'FAILED'}",
    ]
    print("\n".join(lines))  # the command's report (CLI output, not library logging)
    return 0 if ok else 1


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
    synced_at: list[float] = []

    def ready() -> bool:
        if not synced_at and node.clock.synced:
            synced_at.append(time.monotonic())
        return (_ready(mirror.snapshot()) and bool(synced_at)
                and time.monotonic() - synced_at[0] >= CLOCK_SETTLE_S)

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
