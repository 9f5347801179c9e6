"""The mixer: commands array [thrust, torque x, y, z] -> four motor outputs (seed 002 Fig. 2).

The allocation matrix comes from the airframe geometry (Quad X, ArduCopter motor order). When a motor
would saturate, yaw authority is given up first, then the collective is shifted so roll and pitch keep
their torque (attitude before altitude, as ArduCopter's motor mixer does).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, fastmath=True)
def mix(commands, alloc_inv, t_max, idle, out):  # pragma: no cover - numba
    """Per-motor thrust fractions in [idle, 1] from ``commands`` (N, N m); returns 1 if saturated.

    Yaw is scaled down (by halves) until the differential fits the motors' range; then the
    collective is shifted into range, keeping roll and pitch intact; only then is anything clipped.
    """
    thrust = commands[0]
    base = np.empty(4)
    yawc = np.empty(4)
    for i in range(4):
        base[i] = (alloc_inv[i, 0] * thrust + alloc_inv[i, 1] * commands[1]
                   + alloc_inv[i, 2] * commands[2]) / t_max
        yawc[i] = alloc_inv[i, 3] * commands[3] / t_max
    room = 1.0 - idle
    scale = 1.0
    sat = 0
    for _k in range(8):
        lo = 1e9
        hi = -1e9
        for i in range(4):
            v = base[i] + scale * yawc[i]
            lo = min(lo, v)
            hi = max(hi, v)
        if hi - lo <= room or scale == 0.0:
            break
        sat = 1
        scale = 0.5 * scale if _k < 6 else 0.0
    lo = 1e9
    hi = -1e9
    for i in range(4):
        out[i] = base[i] + scale * yawc[i]
        lo = min(lo, out[i])
        hi = max(hi, out[i])
    shift = 0.0
    if hi > 1.0:
        shift = 1.0 - hi
        sat = 1
    if lo + shift < idle:
        shift = idle - lo
        sat = 1
    for i in range(4):
        out[i] = min(max(out[i] + shift, idle), 1.0)
    return sat


class Mixer:
    """Actuators task group module: writes the physics' motor command array."""

    def __init__(self, mx: np.ndarray, my: np.ndarray, spin: np.ndarray, k_q_over_k_t: float,
                 thrust_max_per_motor: float, spin_armed: float = 0.08) -> None:
        alloc = np.vstack([np.ones(4), -my, mx, spin * k_q_over_k_t])
        self.alloc_inv = np.linalg.inv(alloc)
        self.t_max = float(thrust_max_per_motor)
        self.spin_armed = spin_armed

    def step(self, commands: np.ndarray, armed: bool, spooled: bool, motor_cmd: np.ndarray) -> None:
        if not armed:
            motor_cmd[:] = 0.0
            return
        if not spooled:
            motor_cmd[:] = self.spin_armed
            return
        mix(commands, self.alloc_inv, self.t_max, self.spin_armed * 0.5, motor_cmd)
