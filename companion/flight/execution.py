"""Executing one flight command: its channel targets each tick, its end flags and its end condition.

Seed 000 Sec. IV-A (channels, Fig. 7; end condition, Fig. 8) and IV-C (external data). A
:class:`CommandExecution` is created when a command starts; it resolves the command's relative
targets against the reference at that moment, then on every tick

1. turns each channel into a target P_t (:mod:`companion.flight.reference`), reading external
   streams where the mode says so (stale stream: velocity 0, position/heading hold);
2. lets the :class:`~companion.flight.reference.ReferenceGenerator` step the reference;
3. evaluates the end flags H_end, V_end, Hd_end **on the new reference** (arrival of the planned
   trajectory for fixed targets, which is exact; within the tolerances of
   :class:`~companion.flight.limits.Limits` for moving targets) and then the end condition.

Fixed-target channels latch their end flag on arrival and then keep their arrival velocity (the
``end_speed``; zero = hold exactly there) until the command ends. Pausing keeps the resolved
targets, the time already waited (E_Wait counts only running time) and a given confirmation;
:meth:`CommandExecution.resume` replans from the reference the command is resumed at.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .commands import (
    H_END_MODES,
    HD_END_MODES,
    V_END_MODES,
    FlightCommand,
    Frame,
    HeadingMode,
    HorizontalMode,
    SpeedModifier,
    VerticalMode,
)
from .external import ExternalData
from .ground import GroundFollow
from .limits import Limits
from .reference import (
    AxisTarget,
    ChannelTargets,
    PathTarget,
    Reference,
    ReferenceGenerator,
    StepResult,
    VelocityTarget,
    YawRateTarget,
    YawTarget,
    wrap_pi,
)
from .setpoint import Setpoint, SetpointKind, VehicleState

#: Below this horizontal speed (m/s) the flight direction is taken from where the command is going.
_FLIGHT_DIR_MIN_SPEED = 0.5
#: Closer than this (m) to a point, its bearing is undefined and the heading holds.
_POINT_MIN_DISTANCE = 0.5


@dataclass(frozen=True)
class EndFlags:
    """The channel end flags of the last tick (Sec. IV-A4)."""

    h_end: bool = False
    v_end: bool = False
    hd_end: bool = False


@dataclass
class MovingGoals:
    """This tick's goals of the moving-target channels, for their end flags (None: no valid sample)."""

    h_goal: np.ndarray | None = None  # ExtPos: where the horizontal channel is going
    h_center: np.ndarray | None = None  # KeepDistance: the point kept at a distance
    v_goal: float | None = None  # vertical ExtPos: the goal, metres down
    hd_goal: float | None = None  # ExtPos, Point, ExtPoint heading: the goal yaw (rad)


@dataclass(frozen=True)
class TickOutcome:
    """What one tick of a command produced."""

    step: StepResult
    flags: EndFlags
    ended: bool
    land_now: bool


class CommandExecution:
    """The running state of one :class:`FlightCommand` (see module docstring)."""

    # the command's targets, resolved once against the reference it starts from (:meth:`_resolve`)
    h_target: np.ndarray | None  # horizontal Pos: north, east
    h_end_dir: np.ndarray | None
    v_target_down: float | None  # vertical Pos / WithHor: metres down
    hd_target_abs: float | None  # heading Pos: yaw (rad)
    ground: GroundFollow | None = None  # vertical GROUND: the range finder's moving goal (ground.py)

    def __init__(self, command: FlightCommand, start: Reference, limits: Limits) -> None:
        self.command = command
        self.limits = limits
        self.elapsed_s = 0.0
        self.confirmed = False
        self.flags = EndFlags()
        self.ended = False
        self.land_now = False
        self._h_latched = self._v_latched = self._hd_latched = False
        self._hd_passed = False
        #: the altitude the command started from (a take-off's ground)
        self.start_altitude = start.altitude
        #: a take-off: the link reported the lift-off (see CommandQueue.mark_takeoff_airborne)
        self.airborne = False
        self._resolve(start)
        self.resume(start)

    def retarget(self, command: FlightCommand, ref: Reference, changed: frozenset[str]) -> None:
        """Fly ``command`` from now on (Sec. IV-D): re-resolve the ``changed`` channels ("h", "v", "hd"),
        keep the other channels' resolved targets, the waited time and a given confirmation; replan."""
        h_kept, v_kept, hd_kept = self.h_target, self.v_target_down, self.hd_target_abs
        self.command = command
        self._resolve(ref)
        if "h" not in changed:
            self.h_target = h_kept
        if "v" not in changed:
            self.v_target_down = v_kept
        if "hd" not in changed:
            self.hd_target_abs = hd_kept
        self.ended = False
        self.land_now = False
        self.resume(ref)

    # --- resolution ------------------------------------------------------------------------------------
    def _resolve(self, ref: Reference) -> None:
        """Resolve relative targets once, against the reference the command first starts from."""
        c, L = self.command, self.limits
        h, v, hd = c.horizontal, c.vertical, c.heading
        self.h_target = None
        self.h_end_dir = None
        self.h_speed = min(h.speed or L.horizontal_speed, L.horizontal_speed)
        self.h_end_speed = min(h.end_speed or 0.0, self.h_speed)
        if h.mode is HorizontalMode.POS:
            assert h.north is not None and h.east is not None
            if h.resolved_frame is Frame.ABSOLUTE:
                self.h_target = np.array([h.north, h.east], dtype=float)
            elif h.resolved_frame is Frame.RELATIVE:
                self.h_target = np.array([ref.p[0] + h.north, ref.p[1] + h.east])
            else:  # body relative: north = forward, east = right
                cy, sy = math.cos(ref.yaw), math.sin(ref.yaw)
                self.h_target = np.array([ref.p[0] + h.north * cy - h.east * sy,
                                          ref.p[1] + h.north * sy + h.east * cy])
        self.v_target_down = None
        self.ground = None
        self.v_speed = min(v.speed or L.vertical_speed, L.vertical_speed)
        self.v_end_speed = min(v.end_speed or 0.0, self.v_speed)
        if v.mode is VerticalMode.POS:
            assert v.altitude is not None
            alt = v.altitude if v.resolved_frame is Frame.ABSOLUTE else ref.altitude + v.altitude
            self.v_target_down = -float(alt)
        elif v.mode is VerticalMode.WITH_HOR:
            assert v.altitude is not None
            self.v_target_down = -float(v.altitude)
        elif v.mode is VerticalMode.GROUND:
            assert v.altitude is not None
            self.ground = GroundFollow(v.altitude)
        self.hd_target_abs = None
        if hd.mode is HeadingMode.POS:
            assert hd.heading is not None
            rel = hd.resolved_frame is Frame.RELATIVE
            self.hd_target_abs = wrap_pi((ref.yaw if rel else 0.0) + math.radians(hd.heading))

    def resume(self, ref: Reference) -> None:
        """(Re)start from ``ref``: keep resolved targets, waited time and confirmation; replan."""
        c = self.command
        self._h_latched = self._v_latched = self._hd_latched = False
        self._hd_passed = False
        self.flags = EndFlags()
        # straight-line end velocity direction from where we (re)start
        if self.h_target is not None:
            if c.vertical.mode is VerticalMode.WITH_HOR:
                assert self.v_target_down is not None
                d = np.array([*self.h_target, self.v_target_down]) - np.array(ref.p)
            else:
                d = self.h_target - np.array(ref.p[:2])
            n = float(np.linalg.norm(d))
            self.h_end_dir = d / n if n > 1e-9 else None
        self.v_end_dir = 0.0
        if self.ground is not None:
            self.ground.resume()
        if self.v_target_down is not None and c.vertical.mode is VerticalMode.POS:
            self.v_end_dir = float(np.sign(self.v_target_down - ref.p[2]))
        # heading: fix the unwrapped target and the direction of rotation now
        self.hd_yaw_unwrapped: float | None = None
        self.hd_sign = 1.0
        if self.hd_target_abs is not None:
            hd = c.heading
            delta = wrap_pi(self.hd_target_abs - ref.yaw)
            if hd.use_sign and hd.rate is not None:
                if hd.rate > 0 and delta < 0:
                    delta += 2 * math.pi
                elif hd.rate < 0 and delta > 0:
                    delta -= 2 * math.pi
                self.hd_sign = 1.0 if hd.rate > 0 else -1.0
            else:
                self.hd_sign = 1.0 if delta >= 0 else -1.0
            self.hd_yaw_unwrapped = ref.yaw + delta
        self._last_point_yaw: float | None = None

    # --- per tick ---------------------------------------------------------------------------------------
    @property
    def waiting_for_confirmation(self) -> bool:
        return self.command.end.e_user and not self.confirmed and not self.ended

    def confirm(self) -> None:
        self.confirmed = True
        self.ended = self._end_condition(self.flags)

    def step(self, ref: Reference, dt: float, elapsed_dt: float, now_s: float, ext: ExternalData,
             gen: ReferenceGenerator, vehicle: VehicleState | None) -> TickOutcome:
        """Advance one tick: targets, reference step, end flags, end condition."""
        targets, moving = self._targets(ref, now_s, ext, vehicle, dt)
        result = gen.step(ref, targets, dt)
        self.elapsed_s += elapsed_dt
        self.flags = self._end_flags(result, moving, now_s, ext, vehicle)
        self.ended = self._end_condition(self.flags)
        return TickOutcome(result, self.flags, self.ended, self.land_now)

    # --- targets ------------------------------------------------------------------------------------------
    @property
    def failure(self) -> str | None:
        """Why the command cannot go on (the queue fails it), None while it can: V_GROUND's lost range."""
        return self.ground.failure if self.ground is not None else None

    def _targets(self, ref: Reference, now_s: float, ext: ExternalData, vehicle: VehicleState | None = None,
                 dt: float = 0.0) -> tuple[ChannelTargets, MovingGoals]:
        """This tick's P_t; ``moving`` records the moving-target goals for the end flags."""
        c = self.command
        h, v, hd = c.horizontal, c.vertical, c.heading
        moving = MovingGoals()
        p = np.array(ref.p)

        # -- horizontal (and vertical with WithHor)
        horizontal: PathTarget | VelocityTarget = VelocityTarget((0.0, 0.0))
        intended_dir: np.ndarray | None = None
        speed = self.h_speed
        if h.mode is HorizontalMode.POS:
            assert self.h_target is not None
            if self._h_latched:
                end_v = self._end_velocity_h()
                horizontal = VelocityTarget((float(end_v[0]), float(end_v[1])))
            else:
                if v.mode is VerticalMode.WITH_HOR:
                    assert self.v_target_down is not None  # WithHor has an altitude (commands.py)
                    pos: tuple[float, ...] = (float(self.h_target[0]), float(self.h_target[1]),
                                              float(self.v_target_down))
                else:
                    pos = (float(self.h_target[0]), float(self.h_target[1]))
                horizontal = PathTarget(pos, speed, tuple(self._end_velocity_path(len(pos))))
                intended_dir = self.h_target - p[:2]
        elif h.mode in (HorizontalMode.EXT_POS, HorizontalMode.KEEP_DISTANCE):
            sample = ext.latest("ext_pos", now_s)
            if sample is not None:
                tgt = np.array(sample[:2])
                if h.mode is HorizontalMode.EXT_POS:
                    goal = tgt + np.array([h.offset_north or 0.0, h.offset_east or 0.0])
                    moving.h_goal = goal
                else:
                    assert h.distance is not None
                    r = p[:2] - tgt
                    n = float(np.linalg.norm(r))
                    r_unit = r / n if n > 1e-6 else np.array([-1.0, 0.0])
                    goal = tgt + h.distance * r_unit
                    moving.h_center = tgt
                horizontal = PathTarget((float(goal[0]), float(goal[1])), speed, None)
                intended_dir = goal - p[:2]
        elif h.mode in (HorizontalMode.EXT_VEL, HorizontalMode.RC_VEL):
            stream = "ext_vel" if h.mode is HorizontalMode.EXT_VEL else "rc_vel"
            sample = ext.latest(stream, now_s)
            if sample is not None:
                horizontal = VelocityTarget((sample[0], sample[1]))
                intended_dir = np.array(sample[:2])

        # -- vertical
        vertical: AxisTarget | VelocityTarget | None = VelocityTarget((0.0,))
        if v.mode is VerticalMode.WITH_HOR:
            if isinstance(horizontal, PathTarget):
                vertical = None  # part of the 3-D line
            else:
                vertical = VelocityTarget((self._end_velocity_v3(),))
        elif v.mode is VerticalMode.POS:
            assert self.v_target_down is not None
            if self._v_latched:
                vertical = VelocityTarget((self.v_end_dir * self.v_end_speed,))
            else:
                vertical = AxisTarget(self.v_target_down, self.v_speed, self.v_end_dir * self.v_end_speed)
        elif v.mode is VerticalMode.EXT_POS:
            sample = ext.latest("ext_pos", now_s)
            if sample is not None:
                goal_down = sample[2] - (v.offset or 0.0)
                moving.v_goal = goal_down
                vertical = AxisTarget(goal_down, self.v_speed, 0.0)
        elif v.mode in (VerticalMode.EXT_VEL, VerticalMode.RC_VEL):
            sample = ext.latest("ext_vel" if v.mode is VerticalMode.EXT_VEL else "rc_vel", now_s)
            if sample is not None:
                vertical = VelocityTarget((sample[2],))
        elif v.mode is VerticalMode.GROUND:
            assert self.ground is not None
            ground_goal = self.ground.step(vehicle, dt, now_s)
            if ground_goal is not None:  # else hold: come to rest (ground.py)
                moving.v_goal = ground_goal[0]
                ground_v = max(-self.v_speed, min(self.v_speed, ground_goal[1]))
                vertical = AxisTarget(ground_goal[0], self.v_speed, ground_v)

        # -- heading
        heading, hd_goal = self._heading_target(ref, now_s, ext, intended_dir)
        moving.hd_goal = hd_goal

        # -- speed modifiers (Fig. 7)
        h_mods, v_mods = h.speed_modified_by, v.speed_modified_by
        h_sync_hd = SpeedModifier.HEADING in h_mods and hd.mode in (HeadingMode.POS, HeadingMode.EXT_POS)
        flight_dir_sm = SpeedModifier.HEADING in h_mods and hd.mode is HeadingMode.FLIGHT_DIR
        if flight_dir_sm and isinstance(heading, YawTarget):
            # Hd_sm of FlightDir: slow down while the heading is off the flight direction
            err = abs(wrap_pi(heading.yaw - ref.yaw))
            scale = max(0.05, math.cos(min(err, math.pi / 2)))
            if isinstance(horizontal, PathTarget):
                horizontal = PathTarget(horizontal.position, horizontal.speed * scale,
                                        horizontal.end_velocity)
        targets = ChannelTargets(
            horizontal, vertical, heading,
            h_sync_vertical=SpeedModifier.VERTICAL in h_mods,
            h_sync_heading=h_sync_hd,
            v_sync_heading=SpeedModifier.HEADING in v_mods,
            floor_exempt=v.take_off or v.allow_landing)
        return targets, moving

    def _end_velocity_path(self, k: int) -> np.ndarray:
        if self.h_end_dir is None or self.h_end_speed <= 0:
            return np.zeros(k)
        d = self.h_end_dir
        if k == 2:
            return self.h_end_speed * d[:2] / max(float(np.linalg.norm(d[:2])), 1e-9)
        horiz = float(np.linalg.norm(d[:2]))
        if horiz < 1e-6:
            return np.zeros(3)
        return self.h_end_speed / horiz * d

    def _end_velocity_h(self) -> np.ndarray:
        k = 3 if self.command.vertical.mode is VerticalMode.WITH_HOR else 2
        return self._end_velocity_path(k)[:2]

    def _end_velocity_v3(self) -> float:
        if self.command.vertical.mode is VerticalMode.WITH_HOR:
            return float(self._end_velocity_path(3)[2])
        return 0.0

    def _heading_target(self, ref: Reference, now_s: float, ext: ExternalData, intended_dir: np.ndarray | None
                        ) -> tuple[YawTarget | YawRateTarget, float | None]:
        hd, L = self.command.heading, self.limits
        default_rate = L.yaw_rate_rad

        def rate_of(value: float | None) -> float:
            return min(abs(math.radians(value)), default_rate) if value is not None else default_rate

        def towards(absolute_yaw: float, rate: float) -> YawTarget:
            return YawTarget(ref.yaw + wrap_pi(absolute_yaw - ref.yaw), rate)

        mode = hd.mode
        if mode is HeadingMode.POS:
            assert self.hd_yaw_unwrapped is not None
            rate = rate_of(hd.rate)
            if hd.stops:
                if self._hd_latched:
                    return YawRateTarget(0.0), None
                return YawTarget(self.hd_yaw_unwrapped, rate), None
            return YawRateTarget(self.hd_sign * rate), None
        if mode is HeadingMode.FLIGHT_DIR:
            vh = np.array(ref.v[:2])
            direction = vh if float(np.linalg.norm(vh)) >= _FLIGHT_DIR_MIN_SPEED else intended_dir
            if direction is None or float(np.linalg.norm(direction)) < 1e-3:
                return YawRateTarget(0.0), None
            yaw = math.atan2(direction[1], direction[0]) + math.radians(hd.offset or 0.0)
            return towards(yaw, rate_of(hd.rate)), None
        if mode is HeadingMode.EXT_POS:
            sample = ext.latest("ext_heading", now_s)
            if sample is None:
                return YawRateTarget(0.0), None
            yaw = math.radians(sample[0] + (hd.offset or 0.0))
            return towards(yaw, rate_of(hd.speed)), yaw
        if mode in (HeadingMode.EXT_VEL, HeadingMode.RC_VEL):
            sample = ext.latest("ext_vel" if mode is HeadingMode.EXT_VEL else "rc_vel", now_s)
            return YawRateTarget(math.radians(sample[3]) if sample is not None else 0.0), None
        if mode in (HeadingMode.POINT, HeadingMode.EXT_POINT):
            point: tuple[float, ...] | None
            if mode is HeadingMode.POINT:
                assert hd.north is not None and hd.east is not None  # required by Point (commands.py)
                point = (hd.north, hd.east)
            else:
                point = ext.latest("ext_point", now_s)
            if point is None:
                return YawRateTarget(0.0), None
            dn, de = point[0] - ref.p[0], point[1] - ref.p[1]
            if math.hypot(dn, de) < _POINT_MIN_DISTANCE:
                return YawRateTarget(0.0), None
            yaw = math.atan2(de, dn) + math.radians(hd.offset or 0.0)
            return towards(yaw, rate_of(hd.rate)), yaw
        return YawRateTarget(0.0), None  # DNU

    # --- end flags and end condition ------------------------------------------------------------------------
    def _end_flags(self, result: StepResult, moving: MovingGoals, now_s: float, ext: ExternalData,
                   vehicle: VehicleState | None) -> EndFlags:
        c, L = self.command, self.limits
        ref = result.reference
        h, v, hd = c.horizontal, c.vertical, c.heading
        p = np.array(ref.p)
        # horizontal
        if h.mode is HorizontalMode.POS:
            if result.h_arrived and not result.target_unreachable:
                self._h_latched = True
            h_end = self._h_latched
        elif h.mode is HorizontalMode.EXT_POS and moving.h_goal is not None:
            h_end = float(np.linalg.norm(p[:2] - moving.h_goal)) <= L.arrival_tolerance \
                and not result.target_unreachable
        elif h.mode is HorizontalMode.KEEP_DISTANCE and moving.h_center is not None:
            assert h.distance is not None
            off = abs(float(np.linalg.norm(p[:2] - moving.h_center)) - h.distance)
            h_end = off <= L.arrival_tolerance and not result.target_unreachable
        else:
            h_end = False
        # vertical
        if v.mode is VerticalMode.WITH_HOR:
            if result.v_arrived and not result.target_unreachable:
                self._v_latched = True
            v_end = self._v_latched and h_end
        elif v.mode is VerticalMode.POS:
            if result.v_arrived and not result.target_unreachable:
                self._v_latched = True
            v_end = self._v_latched
            if v.allow_landing:
                landed = vehicle.landed if vehicle is not None else None
                if self._v_latched or landed is True:
                    self.land_now = True
                # touchdown ends the landing: the vehicle's report when it has one, else the reference
                v_end = landed is True or (landed is None and self._v_latched)
        elif v.mode in (VerticalMode.EXT_POS, VerticalMode.GROUND) and moving.v_goal is not None:
            off = abs(ref.p[2] - moving.v_goal)
            v_end = off <= L.arrival_tolerance and not result.target_unreachable
        else:
            v_end = False
        # heading
        tol = math.radians(L.heading_tolerance)
        if hd.mode is HeadingMode.POS:
            assert self.hd_yaw_unwrapped is not None
            if hd.stops:
                if result.hd_arrived:
                    self._hd_latched = True
                hd_end = self._hd_latched
            else:
                if (ref.yaw - self.hd_yaw_unwrapped) * self.hd_sign >= 0:
                    self._hd_passed = True
                hd_end = self._hd_passed
        elif moving.hd_goal is not None:  # EXT_POS, POINT, EXT_POINT with a valid goal
            hd_end = abs(wrap_pi(ref.yaw - moving.hd_goal)) <= tol
        else:
            hd_end = False
        return EndFlags(h_end, v_end, hd_end)

    def _end_condition(self, flags: EndFlags) -> bool:
        """Fig. 8: (channel element) and (E_User) and (E_Wait); see commands.py for E_Any."""
        e, c = self.command.end, self.command
        selected = [(flag, value) for flag, value in (("e_h", flags.h_end), ("e_v", flags.v_end),
                                                        ("e_hd", flags.hd_end)) if getattr(e, flag)]
        if e.e_any:
            pool = selected or [("e_h", flags.h_end) if c.horizontal.mode in H_END_MODES else ("e_h", False),
                                ("e_v", flags.v_end) if c.vertical.mode in V_END_MODES else ("e_v", False),
                                ("e_hd", flags.hd_end) if c.heading.mode in HD_END_MODES else ("e_hd", False)]
            channel_ok = any(value for _, value in pool)
        else:
            channel_ok = all(value for _, value in selected)
        user_ok = self.confirmed if e.e_user else True
        wait_ok = self.elapsed_s >= e.e_wait - 1e-9 if e.e_wait is not None else True
        return channel_ok and user_ok and wait_ok


def streamed_setpoint(ref: Reference, execution: CommandExecution | None, land_now: bool, *,
                      index: int | None, command_id: int | None, routine_id: str | None) -> Setpoint:
    """The reference as the link streams it (P_d, Fig. 9) while ``execution`` runs (None: holding).

    ``index`` and ``command_id`` name the producing command of the list, ``routine_id`` the pause
    routine producing it (:class:`~.setpoint.Setpoint`)."""
    kind = SetpointKind.POSITION
    take_off = allow_landing = False
    takeoff_alt = None
    if execution is not None:
        cmd = execution.command
        if cmd.velocity_only:
            kind = SetpointKind.VELOCITY
        take_off = cmd.vertical.take_off
        allow_landing = cmd.vertical.allow_landing
        if take_off and execution.v_target_down is not None:
            takeoff_alt = -execution.v_target_down
    return Setpoint(ref.t_s, ref.p, ref.v, ref.a, wrap_pi(ref.yaw), ref.yaw_rate, kind, take_off,
                    takeoff_alt, allow_landing, land_now, index, routine_id, command_id)
