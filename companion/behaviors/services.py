"""The bundled execution processes (seed 001 Sec. 6.2.3): in-process services behaviors start and stop.

* ``motion_controller``: the flight-command queue executing and streaming (seed 000's QAPI). Started:
  the queue runs; stopped (no behavior needs it, e.g. after landing): the queue stops, the reference
  comes to rest where it is.
* ``trajectory_planner``: plans the legs of GO_TO_POINT and FOLLOW_PATH inside the operational
  envelope: every leg is the straight 3-D line, which must stay inside the envelope's polygon and
  altitude band (a non-convex envelope can make a point unreachable this way; there is no routing
  around corners yet). Refuses to plan while stopped.
* ``velocity_source``: KEEP_MOVING's constant velocity, pushed as ``ext_vel`` samples on every monitor
  tick with a short validity, so the vehicle stops within half a second of the source stopping.
* ``joystick_feed``: the operator's stick samples for FOLLOW_EXTERNAL_VELOCITY, accepted only while a
  behavior uses the feed (otherwise :class:`~.processes.ProcessError`), forwarded as ``ext_vel``.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from companion.flight.limits import Envelope
from companion.flight.qapi import QueueStateError

from .controller import UnreachableError
from .processes import ExecutionProcess, ProcessError

if TYPE_CHECKING:
    from companion.flight.queue import CommandQueue

log = logging.getLogger(__name__)

Vec3 = tuple[float, float, float]
#: Validity of the samples the velocity source and the joystick feed push (s of queue time).
SAMPLE_VALIDITY_S = 0.5


class NoPathError(UnreachableError):
    """The trajectory planner found no path to a point."""


class MotionController(ExecutionProcess):
    name = "motion_controller"

    def __init__(self, queue: CommandQueue) -> None:
        super().__init__()
        self.queue = queue

    def on_start(self) -> None:
        try:
            self.queue.run()
        except QueueStateError as exc:
            raise ProcessError(f"motion_controller: {exc}") from None

    def on_stop(self) -> None:
        self.queue.stop()


class TrajectoryPlanner(ExecutionProcess):
    name = "trajectory_planner"

    def __init__(self, envelope: Envelope) -> None:
        super().__init__()
        self.envelope = envelope
        self.plans = 0
        self.last_plan: list[Vec3] = []

    def plan(self, start_neu: Vec3, points_neu: Sequence[Vec3]) -> list[Vec3]:
        """The legs from ``start`` through ``points`` ((north, east, up) each), checked in the envelope."""
        if not self.running:
            raise ProcessError("trajectory_planner is not running")
        legs: list[Vec3] = []
        prev = start_neu
        for i, p in enumerate(points_neu):
            what = f"point {i + 1} ({p[0]:g}, {p[1]:g}, {p[2]:g})" if len(points_neu) > 1 else \
                f"({p[0]:g}, {p[1]:g}, {p[2]:g})"
            _, moved = self.envelope.clamp_altitude(p[2])
            if moved:
                raise NoPathError(f"{what}: altitude outside the envelope's band")
            if not self.envelope.contains_ne(p[:2]):
                raise NoPathError(f"{what} lies outside the operational envelope")
            if not self.envelope.covers_segment(prev[:2], p[:2]):
                raise NoPathError(f"{what}: the straight line leaves the operational envelope "
                             "(no routing around its corners)")
            legs.append(p)
            prev = p
        self.plans += 1
        self.last_plan = legs
        return legs

    def status(self) -> dict[str, Any]:
        return {**super().status(), "plans": self.plans}


class VelocitySource(ExecutionProcess):
    name = "velocity_source"

    def __init__(self, queue: CommandQueue) -> None:
        super().__init__()
        self.queue = queue
        self.velocity_ned: Vec3 = (0.0, 0.0, 0.0)
        self.pushed = 0

    def set_velocity(self, velocity_neu: Vec3) -> None:
        self.velocity_ned = (float(velocity_neu[0]), float(velocity_neu[1]), -float(velocity_neu[2]))
        self.tick(0.0)

    def on_stop(self) -> None:
        self.velocity_ned = (0.0, 0.0, 0.0)

    def tick(self, now_s: float) -> None:
        if self.running:
            self.queue.push_external("ext_vel", (*self.velocity_ned, 0.0), SAMPLE_VALIDITY_S)
            self.pushed += 1


class JoystickFeed(ExecutionProcess):
    name = "joystick_feed"

    def __init__(self, queue: CommandQueue) -> None:
        super().__init__()
        self.queue = queue
        self.samples = 0

    def push(self, values: Sequence[float], validity_s: float = SAMPLE_VALIDITY_S) -> bool:
        """A stick sample ``(v_north, v_east, v_down, yaw_rate_deg_s)``; refused unless a behavior uses it;
        False (ignored) while the behavior follows another source (its ``source``)."""
        if not self.running:
            raise ProcessError("joystick_feed is not running (activate FOLLOW_EXTERNAL_VELOCITY first)")
        self.samples += 1
        return self.queue.push_external("ext_vel", values, min(validity_s, SAMPLE_VALIDITY_S),
                                        source="joystick")

    def status(self) -> dict[str, Any]:
        return {**super().status(), "samples": self.samples}


def bundled_processes(queue: CommandQueue, envelope: Envelope) -> list[ExecutionProcess]:
    return [MotionController(queue), TrajectoryPlanner(envelope), VelocitySource(queue), JoystickFeed(queue)]
