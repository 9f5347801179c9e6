"""Helpers to fly the queue without an autopilot, and to check the streamed setpoints' continuity.

:class:`PointMass` is the project's one kinematic stand-in for a vehicle: a point in NED metres with
speed, acceleration and climb limits, steered toward a target or tracking a setpoint (the team
simulator's vehicles, :class:`FlightSim` and the tests' stand-in navigator use it).
:class:`FlightSim` ticks a :class:`~companion.flight.queue.CommandQueue` on simulated time with the
point mass tracking the setpoint with a one-tick delay (``landed`` on the ground).
:func:`step_violations` checks a recorded setpoint stream against the step bounds of seed 000
Sec. IV-D as :mod:`companion.flight.reference` states them (the bounds its guard clamps every step to);
:func:`jerk_violations` checks the jerk limits, which only the planner keeps; the link's integration tests
can apply both to what was really streamed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from .limits import Limits
from .queue import CommandQueue
from .reference import wrap_pi
from .setpoint import Setpoint, SetpointKind, VehicleState


@dataclass(frozen=True)
class Violation:
    """One pair of consecutive setpoints breaking a bound: ``quantity`` moved ``value`` > ``bound``."""

    index: int
    t_s: float
    quantity: str
    value: float
    bound: float


def step_violations(setpoints: Sequence[Setpoint], limits: Limits, rel_tol: float = 1e-9,
                    abs_tol: float = 1e-12) -> list[Violation]:
    """All violations of |dv| <= a_max*dt, |dp| <= v_max*dt (horizontal norm, vertical) and
    |dyaw| <= yaw_rate*dt between consecutive setpoints (dt from their time stamps). Positions are
    compared between position setpoints only: a velocity-only setpoint gives the autopilot none (as
    the wire check does). A step is a violation when it exceeds ``bound * (1 + rel_tol) + abs_tol``:
    ``abs_tol`` absorbs the quantisation of setpoints read back from a log (the generator's guard
    clamps a step to exactly its bound, so rounding alone can push a logged step past it)."""
    out: list[Violation] = []
    L = limits
    for i in range(1, len(setpoints)):
        s0, s1 = setpoints[i - 1], setpoints[i]
        dt = s1.t_s - s0.t_s
        if dt <= 0:
            if s0 != s1:
                out.append(Violation(i, s1.t_s, "time", dt, 0.0))
            continue
        checks = [
            ("dv_h", math.hypot(s1.v[0] - s0.v[0], s1.v[1] - s0.v[1]), L.horizontal_acceleration * dt),
            ("dv_v", abs(s1.v[2] - s0.v[2]), L.vertical_acceleration * dt),
            ("dyaw", abs(wrap_pi(s1.yaw - s0.yaw)), math.radians(L.yaw_rate) * dt),
        ]
        if s0.kind is SetpointKind.POSITION and s1.kind is SetpointKind.POSITION:  # as on the wire
            checks += [("dp_h", math.hypot(s1.p[0] - s0.p[0], s1.p[1] - s0.p[1]), L.horizontal_speed * dt),
                       ("dp_v", abs(s1.p[2] - s0.p[2]), L.vertical_speed * dt)]
        for name, value, bound in checks:
            if value > bound * (1.0 + rel_tol) + abs_tol:
                out.append(Violation(i, s1.t_s, name, value, bound))
    return out


def jerk_violations(setpoints: Sequence[Setpoint], limits: Limits, rel_tol: float = 1e-6) -> list[Violation]:
    """All changes of the acceleration feed-forward between consecutive position setpoints beyond the jerk
    limits: |da_h| <= j_h,max*dt (horizontal norm) and |da_v| <= j_v,max*dt.

    The generator's guard does not enforce these (it clamps the steps :func:`step_violations` checks), the
    planner's jerk-limited trajectories do (seed 000 Sec. IV-D): a stream that passes both was continuous by
    its plans, not because the guard clamped it."""
    out: list[Violation] = []
    for i in range(1, len(setpoints)):
        s0, s1 = setpoints[i - 1], setpoints[i]
        dt = s1.t_s - s0.t_s
        if dt <= 0 or s0.kind is not SetpointKind.POSITION or s1.kind is not SetpointKind.POSITION:
            continue
        for name, value, bound in (
                ("da_h", math.hypot(s1.a[0] - s0.a[0], s1.a[1] - s0.a[1]), limits.horizontal_jerk * dt),
                ("da_v", abs(s1.a[2] - s0.a[2]), limits.vertical_jerk * dt)):
            if value > bound * (1.0 + rel_tol):
                out.append(Violation(i, s1.t_s, name, value, bound))
    return out


Vec3 = tuple[float, float, float]


@dataclass
class PointMass:
    """A kinematic vehicle: position ``p`` and velocity ``v`` in NED (m, m/s) under the limits
    ``speed`` (horizontal), ``accel`` (horizontal) and ``climb_speed`` (vertical)."""

    p: Vec3 = (0.0, 0.0, 0.0)
    speed: float = 5.0
    accel: float = 2.5
    climb_speed: float = 2.5
    v: Vec3 = (0.0, 0.0, 0.0)

    def fly_toward(self, target: Sequence[float], dt: float) -> float:
        """One step of ``dt`` s toward ``target``: horizontally under the speed and acceleration limits,
        braking to stop at it; vertically at up to ``climb_speed``. Returns the horizontal metres moved."""
        dn, de, dd = target[0] - self.p[0], target[1] - self.p[1], target[2] - self.p[2]
        dist = math.hypot(dn, de)
        want_n = want_e = 0.0
        if dist > 1e-6:
            k = min(self.speed, math.sqrt(2.0 * self.accel * dist), dist / dt) / dist
            want_n, want_e = dn * k, de * k
        dvn, dve = want_n - self.v[0], want_e - self.v[1]
        n = math.hypot(dvn, dve)
        if n > self.accel * dt:
            dvn, dve = dvn * self.accel * dt / n, dve * self.accel * dt / n
        vd = max(-self.climb_speed, min(self.climb_speed, dd / dt))
        self.v = (self.v[0] + dvn, self.v[1] + dve, vd)
        step = (self.v[0] * dt, self.v[1] * dt, self.v[2] * dt)
        self.p = (self.p[0] + step[0], self.p[1] + step[1], self.p[2] + step[2])
        return math.hypot(step[0], step[1])

    def straight_toward(self, target: Sequence[float], dt: float) -> bool:
        """One step of ``dt`` s along the straight line to ``target`` at ``speed`` (no acceleration, no
        separate climb limit: a navigator's idealisation); True once at it."""
        d = math.dist(self.p, target)
        k = min(1.0, self.speed * dt / d) if d > 0 else 1.0
        step = (k * (target[0] - self.p[0]), k * (target[1] - self.p[1]), k * (target[2] - self.p[2]))
        self.p = (self.p[0] + step[0], self.p[1] + step[1], self.p[2] + step[2])
        if dt > 0:
            self.v = (step[0] / dt, step[1] / dt, step[2] / dt)
        return k == 1.0

    def track(self, p: Sequence[float], v: Sequence[float], ground_down: float = 0.0) -> None:
        """Be at ``p`` with velocity ``v`` (a perfect tracker of a setpoint; the ground, at NED down
        ``ground_down``, stops it)."""
        self.p = (float(p[0]), float(p[1]), min(float(p[2]), ground_down))
        self.v = (float(v[0]), float(v[1]), float(v[2]))


@dataclass
class FlightSim:
    """Tick ``queue`` every ``dt`` seconds of simulated time; the vehicle follows one tick behind.

    ``ground_altitude`` is where the vehicle stands (``landed`` is reported at or below it).
    Every setpoint is kept in ``setpoints``; ``on_tick`` callbacks run before each tick (feed
    external data there).
    """

    queue: CommandQueue
    dt: float = 0.05
    t: float = 0.0
    yaw: float = 0.0
    ground_altitude: float = 0.0
    setpoints: list[Setpoint] = field(default_factory=list)
    on_tick: list[Callable[[FlightSim], None]] = field(default_factory=list)
    #: the vehicle, tracking each setpoint exactly one tick later
    body: PointMass = field(default_factory=PointMass)

    @property
    def p(self) -> Vec3:
        return self.body.p

    @p.setter
    def p(self, value: Vec3) -> None:
        self.body.p = value  # a teleport (a vehicle moved by someone else)

    @property
    def landed(self) -> bool:
        return -self.p[2] <= self.ground_altitude + 0.02

    def state(self) -> VehicleState:
        return VehicleState(self.body.p, self.body.v, self.yaw, self.landed)

    def tick(self) -> Setpoint | None:
        for cb in self.on_tick:
            cb(self)
        sp = self.queue.tick(self.t, self.state())
        if sp is not None:
            self.setpoints.append(sp)
            self.body.track(sp.p, sp.v, -self.ground_altitude)
            self.yaw = sp.yaw
        self.t = round(self.t + self.dt, 9)
        return sp

    def run_for(self, seconds: float) -> Setpoint | None:
        sp = None
        for _ in range(max(1, round(seconds / self.dt))):
            sp = self.tick()
        return sp

    def run_until(self, predicate: Callable[[FlightSim], bool], timeout_s: float) -> float:
        """Tick until ``predicate(self)``; returns the simulated time; raises TimeoutError."""
        end = self.t + timeout_s
        while self.t <= end:
            self.tick()
            if predicate(self):
                return self.t
        raise TimeoutError(f"not reached within {timeout_s} s (t={self.t:.2f}, status={self.queue.status()})")

    @property
    def last(self) -> Setpoint:
        return self.setpoints[-1]
