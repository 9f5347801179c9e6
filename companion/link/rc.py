"""The pilot's sticks as the ``rc_vel`` external stream (seed 000 Fig. 7: the RC_VEL channel modes).

Seed 000 Fig. 7 lets each channel take its velocity from the RC transmitter (H_RCVel, V_RCVel,
Hd_RCVel). The autopilot reports the sticks in RC_CHANNELS (PWM microseconds, ArduPilot's channel
map RCMAP: roll 1, pitch 2, throttle 3, yaw 4); :func:`rc_velocity` turns one report into the
``rc_vel`` sample (v_north, v_east, v_down in m/s, yaw rate in deg/s) that the RC_VEL modes read:

* each stick is centred at ``trim_us``; inside ``deadband_us`` it reads zero (ArduPilot's RCn_DZ,
  30 us by default), beyond it the deflection is scaled linearly to +-1 at ``min_us`` / ``max_us``
  (1100 / 1900, ArduPilot's defaults) and clipped;
* pitch forward (low PWM) flies forward and roll right (high PWM) flies right, *of the vehicle's
  heading* (a pilot flies from the vehicle's point of view), turned into north / east with the yaw;
  throttle above centre climbs (ArduCopter's position modes: a centred throttle holds altitude);
  yaw right turns clockwise;
* the full deflection is the flight limits' speed and yaw rate (:class:`~companion.flight.Limits`).

A report with fewer than four channels, an unused channel (0 or 65535) or no signal (RSSI 0) gives
no sample: the stream goes stale after its validity and the RC_VEL channels stop (Sec. IV-C).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from companion.flight import Limits

#: RC_CHANNELS values that mean "no value" in MAVLink
_UNUSED = (0, 65535)


@dataclass(frozen=True)
class RcMapping:
    """Channel numbers (1-based, ArduPilot's RCMAP) and stick calibration (ArduPilot's RCn defaults)."""

    roll: int = 1
    pitch: int = 2
    throttle: int = 3
    yaw: int = 4
    min_us: float = 1100.0
    trim_us: float = 1500.0
    max_us: float = 1900.0
    deadband_us: float = 30.0
    validity_s: float = 0.5

    def __post_init__(self) -> None:
        channels = (self.roll, self.pitch, self.throttle, self.yaw)
        if len(set(channels)) != 4 or not all(1 <= c <= 18 for c in channels):
            raise ValueError(f"rc mapping: four different channels in 1..18 expected, got {channels}")
        if not self.min_us < self.trim_us - self.deadband_us < self.trim_us + self.deadband_us < self.max_us:
            raise ValueError("rc mapping: min_us < trim_us - deadband_us and trim_us + deadband_us < max_us")

    def stick(self, pwm: float) -> float:
        """One stick's deflection in -1..1 (0 inside the deadband)."""
        off = pwm - self.trim_us
        if abs(off) <= self.deadband_us:
            return 0.0
        span = (self.max_us if off > 0 else self.trim_us) - (self.trim_us if off > 0 else self.min_us)
        x = (abs(off) - self.deadband_us) / (span - self.deadband_us)
        return math.copysign(min(x, 1.0), off)


def rc_velocity(channels: Sequence[int], yaw_rad: float, limits: Limits, mapping: RcMapping | None = None,
                rssi: int = 255) -> tuple[float, float, float, float] | None:
    """The ``rc_vel`` sample for one RC_CHANNELS report (see module docstring), or None."""
    mapping = mapping or RcMapping()
    if rssi == 0:
        return None
    try:
        raw = [channels[c - 1] for c in (mapping.roll, mapping.pitch, mapping.throttle, mapping.yaw)]
    except IndexError:
        return None
    if any(v in _UNUSED for v in raw):
        return None
    roll, pitch, throttle, yaw = (mapping.stick(v) for v in raw)
    forward = -pitch * limits.horizontal_speed
    right = roll * limits.horizontal_speed
    norm = math.hypot(forward, right)
    if norm > limits.horizontal_speed:  # a diagonal stick is no faster than the limit
        forward, right = forward * limits.horizontal_speed / norm, right * limits.horizontal_speed / norm
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    v_north = forward * c - right * s
    v_east = forward * s + right * c
    v_down = -throttle * limits.vertical_speed
    return (v_north, v_east, v_down, yaw * limits.yaw_rate)
