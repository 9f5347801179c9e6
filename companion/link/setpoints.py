"""Setpoints as SET_POSITION_TARGET_LOCAL_NED, and the is_synced check on the autopilot's echo.

Seed 000 Fig. 9: the reference P_d = [p_d, v_d, a_d] (+ yaw) goes to the autopilot's controller. In
ArduCopter GUIDED (``GCS_MAVLINK_Copter::handle_message``, "Copter Commands in Guided Mode") each of
position, velocity and acceleration is ignored if *any* of its three ``type_mask`` bits is set, so we
set all three or none; position + velocity + acceleration selects the PosVelAccel sub-mode (the
velocity and acceleration are feed-forward), velocity alone the VelAccel one. Yaw and yaw rate may
be given together (angle with a rate feed-forward). Frame: MAV_FRAME_LOCAL_NED, metres from the EKF
origin, the frame of LOCAL_POSITION_NED.

is_synced (Sec. V): the autopilot follows what we stream when its POSITION_TARGET_LOCAL_NED echoes a
target we sent recently; :class:`SyncTracker` keeps the last second of sent targets. An autopilot does
not echo the target as sent: ArduCopter's pos-vel-accel GUIDED (``AC_PosControl::input_pos_vel_accel``)
advances it every loop by its velocity and acceleration feed-forward, so the echo stamped
``time_boot_ms`` is compared with each sent target *extrapolated to that time*
(p + v dt + a dt^2 / 2), within ``tolerance_m`` plus ``timing_s`` of the target's speed (our estimate
of the autopilot's clock and the echo's stamp differ by a few milliseconds).
"""

from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.flight.setpoint import Setpoint, SetpointKind

from .mirror import PositionTargetEcho

M = mavlink
IGNORE_POS = 0b111
IGNORE_VEL = 0b111 << 3
IGNORE_ACC = 0b111 << 6
FORCE_SET = 1 << 9
IGNORE_YAW = 1 << 10
IGNORE_YAW_RATE = 1 << 11

#: position + velocity + acceleration feed-forward + yaw + yaw rate: nothing ignored.
MASK_POSITION = 0
#: velocity only (+ yaw rate): ExtVel / RCVel on the horizontal and vertical channels.
MASK_VELOCITY = IGNORE_POS | IGNORE_ACC | IGNORE_YAW


@dataclass(frozen=True)
class TargetFields:
    """The fields of one SET_POSITION_TARGET_LOCAL_NED (frame LOCAL_NED)."""

    type_mask: int
    p: tuple[float, float, float]
    v: tuple[float, float, float]
    a: tuple[float, float, float]
    yaw: float
    yaw_rate: float


def target_fields(sp: Setpoint) -> TargetFields:
    """Encode a queue setpoint (see module docstring for the masks)."""
    if sp.kind is SetpointKind.VELOCITY:
        return TargetFields(MASK_VELOCITY, (0.0, 0.0, 0.0), sp.v, (0.0, 0.0, 0.0), 0.0, sp.yaw_rate)
    yaw = math.atan2(math.sin(sp.yaw), math.cos(sp.yaw))
    return TargetFields(MASK_POSITION, sp.p, sp.v, sp.a, yaw, sp.yaw_rate)


class SyncTracker:
    """Matches the autopilot's POSITION_TARGET_LOCAL_NED echo against recently sent targets."""

    def __init__(self, window_s: float = 1.0, tolerance_m: float = 0.05, stale_s: float = 1.0,
                 timing_s: float = 0.05) -> None:
        self.window_s = window_s
        self.tolerance = tolerance_m
        self.timing_s = timing_s
        self.stale_s = stale_s
        self._lock = threading.Lock()
        self._sent: deque[tuple[float, TargetFields]] = deque()
        self._last_match_s: float | None = None
        self._last_sent_s: float | None = None
        self._seen_echo: PositionTargetEcho | None = None
        self.echoes = 0
        self.matches = 0
        #: the distance of the last echo from the best extrapolated target (m or m/s)
        self.last_error: float | None = None

    def sent(self, t_s: float, fields: TargetFields) -> None:
        with self._lock:
            self._sent.append((t_s, fields))
            self._last_sent_s = t_s
            while self._sent and self._sent[0][0] < t_s - self.window_s:
                self._sent.popleft()

    def echo(self, echo: PositionTargetEcho, now_s: float) -> None:
        """An echo arrived (called with each new one); ``now_s`` is our estimate of the autopilot's time."""
        with self._lock:
            if echo == self._seen_echo:
                return
            self._seen_echo = echo
            self.echoes += 1
            t_echo = echo.time_boot_ms * 1e-3
            errors = [self._error(f, echo, t_echo - t) for t, f in self._sent
                      if -self.timing_s <= t_echo - t <= self.window_s]
            best = min(errors, key=lambda e: e[0] - e[1], default=None)
            self.last_error = best[0] if best is not None else None
            if best is not None and best[0] <= best[1]:
                self._last_match_s = now_s
                self.matches += 1

    def _error(self, f: TargetFields, echo: PositionTargetEcho, dt: float) -> tuple[float, float]:
        """(distance of the echo from ``f`` advanced by ``dt``, the tolerance); inf when not comparable."""
        dt = max(dt, 0.0)
        if not f.type_mask & IGNORE_POS:
            if echo.type_mask & IGNORE_POS:
                return math.inf, 0.0
            pred = tuple(p + v * dt + 0.5 * a * dt * dt for p, v, a in zip(f.p, f.v, f.a, strict=True))
            speed = math.hypot(*f.v)
            return math.dist(pred, echo.p), self.tolerance + self.timing_s * speed
        if echo.type_mask & IGNORE_VEL:
            return math.inf, 0.0
        return math.dist(f.v, echo.v), self.tolerance

    def synced(self, now_s: float) -> bool:
        """A matching echo within ``stale_s`` while we are streaming."""
        with self._lock:
            if self._last_match_s is None or self._last_sent_s is None:
                return False
            return now_s - self._last_match_s <= self.stale_s and now_s - self._last_sent_s <= self.stale_s

    def clear(self) -> None:
        with self._lock:
            self._sent.clear()
            self._last_match_s = None
