"""Simulated sensors (sensors task group, seed 002 Sec. 2): IMU, GPS, barometer, compass, and an indoor
motion-capture position source.

Each sensor samples the true state of the world (:class:`~autopilot_model.physics.quadrotor.Quadrotor`)
and adds configurable noise, bias and latency; the estimator only ever sees these samples. Gaussian
noise is drawn in blocks with numpy so each sample costs an index, not a random-number call.

A sensor profile (:data:`PROFILES`) holds noise figures only. Which position source flies (GPS or motion
capture) and every sensor's rate come from the module library (``config/modules.yaml``, seed 002 Sec. 3.2):
the profile of the same name is a module there that depends on its position source, the resolver loads
``gps`` or ``mocap`` (they provide ``@position_source`` and conflict), and each sensor function runs at
the frequency of its module, its prescaler in the static schedule. The vehicle hands the resolved
source and the periods to the sensors and the estimator (``Vehicle.start``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numba import njit

from autopilot_model.physics.quadrotor import PX, PY, PZ, QW, QX, QY, QZ, VX, VY, VZ, Quadrotor
from autopilot_model.quatmath import quat_yaw


class NoiseSource:
    """Blocks of standard normal samples from a seeded generator."""

    BLOCK = 8192

    def __init__(self, seed: int | None, width: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.width = width
        self._buf = self.rng.standard_normal((self.BLOCK, width))
        self._i = 0

    def next(self) -> np.ndarray:
        if self._i >= self.BLOCK:
            self._buf = self.rng.standard_normal((self.BLOCK, self.width))
            self._i = 0
        row = self._buf[self._i]
        self._i += 1
        return row


@dataclass
class SensorNoise:
    """Noise figures of one sensor profile (1-sigma)."""

    gyro: float = 0.003          # rad/s
    gyro_bias: float = 0.002     # rad/s, constant per run
    accel: float = 0.05          # m/s^2
    accel_bias: float = 0.02     # m/s^2
    pos_latency_s: float = 0.1
    pos_h: float = 0.3           # m, white
    pos_v: float = 0.5           # m
    pos_walk: float = 0.0        # m, correlated (Gauss-Markov, 30 s) part of the position error
    vel: float = 0.1             # m/s (GPS velocity; mocap gives none)
    baro: float = 0.1            # m
    heading: float = 0.01        # rad


@njit(cache=True, fastmath=True)
def imu_sample(x, f, n, gb, ab, ng, na, gyro, accel):  # pragma: no cover - numba
    """gyro = true rates + bias + noise; accel = true specific force + bias + noise."""
    for k in range(3):
        gyro[k] = x[10 + k] + gb[k] + ng * n[k]
        accel[k] = f[k] + ab[k] + na * n[3 + k]


class Imu:
    """Gyroscope and accelerometer: truth + constant bias + white noise, at the main-loop rate."""

    def __init__(self, world: Quadrotor, noise: SensorNoise, seed: int | None) -> None:
        self.world = world
        self.noise = noise
        self.src = NoiseSource(seed, 6)
        b = np.random.default_rng(None if seed is None else seed + 100).standard_normal(6)
        self.gyro_bias = b[:3] * noise.gyro_bias
        self.accel_bias = b[3:] * noise.accel_bias
        self.gyro = np.zeros(3)
        self.accel = np.array([0.0, 0.0, -9.80665])

        self._ng = float(noise.gyro)
        self._na = float(noise.accel)

    def periodic(self) -> None:
        imu_sample(self.world.x, self.world.out, self.src.next(), self.gyro_bias, self.accel_bias, self._ng,
                   self._na, self.gyro, self.accel)


class PositionSensor:
    """GPS (or motion capture) position and velocity with white and correlated noise and a latency.

    ``sample`` is the newest measurement delivered to the estimator (valid ``latency`` after it was
    taken); ``fresh`` is set when a new one arrives and cleared by the consumer. GPS health
    (fix type, satellites, eph/epv) is reported for telemetry and pre-arm checks.

    :meth:`configure` gives it the module the resolver loaded (``gps`` or ``mocap``) and its period in
    the schedule; :meth:`periodic` is called at that rate by the main loop (no rate gate here).
    """

    def __init__(self, world: Quadrotor, noise: SensorNoise, seed: int | None) -> None:
        self.world = world
        self.noise = noise
        self.src = NoiseSource(seed, 8)
        self.walk = [0.0, 0.0, 0.0]
        self._pending: deque[tuple[float, tuple[float, ...]]] = deque()
        self.sample: tuple[float, ...] | None = None  # (n, e, d, vn, ve, vd)
        self.sample_time = 0.0  # when the sample was taken (sim s)
        self.fresh = False
        self.fix_type = 0
        self.satellites = 0
        self.enabled = True
        self.module = ""
        """The module providing ``@position_source`` (``gps`` or ``mocap``), set by :meth:`configure`."""
        self.is_gps = False
        self.eph_m = noise.pos_h * 2.0
        self.epv_m = noise.pos_v * 2.0
        self.time_s = 0.0
        self.dt = math.nan
        """Sample period (s): the step of the source's function in the schedule (:meth:`configure`)."""

    def configure(self, module: str, dt: float) -> None:
        """The position source module the resolver loaded and the period of its function (s)."""
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"position source period must be positive, got {dt!r}")
        self.module = module
        self.is_gps = module == "gps"
        self.dt = float(dt)

    def periodic(self, now_s: float) -> None:
        """Take a sample (called by the schedule at the source's rate) and deliver those whose latency
        elapsed."""
        self.time_s = now_s
        if not self.enabled:
            self.fix_type = 0
            self.satellites = 0
            return
        nz = self.noise
        n = self.src.next()
        x = self.world.x
        if nz.pos_walk > 0:
            a = self.dt / 30.0
            s = nz.pos_walk * math.sqrt(2 * a)
            for k in range(3):
                self.walk[k] += -self.walk[k] * a + s * n[5 + k] * (1.0 if k < 2 else 1.5)
        meas = (
            x[PX] + nz.pos_h * n[0] + self.walk[0],
            x[PY] + nz.pos_h * n[1] + self.walk[1],
            x[PZ] + nz.pos_v * n[2] + self.walk[2],
            x[VX] + nz.vel * n[3],
            x[VY] + nz.vel * n[4],
            x[VZ] + nz.vel * n[3] * 0.5 + nz.vel * n[4] * 0.5,
        )
        self._pending.append((now_s, meas))
        while self._pending and now_s - self._pending[0][0] >= nz.pos_latency_s - 1e-9:
            self.sample_time, self.sample = self._pending.popleft()
            self.fresh = True
        self.fix_type = 3 if self.sample is not None else 0
        self.satellites = 14 if self.sample is not None else 0


class Barometer:
    """Altitude (m up from home) with white noise and a slow drift."""

    def __init__(self, world: Quadrotor, noise: SensorNoise, seed: int | None) -> None:
        self.world = world
        self.noise = noise
        self.src = NoiseSource(seed, 2)
        self.drift = 0.0
        self.alt = 0.0
        self.fresh = False

    def periodic(self) -> None:
        n = self.src.next()
        self.drift += 0.002 * n[1]
        self.alt = -self.world.x[PZ] + self.noise.baro * n[0] + self.drift
        self.fresh = True


class Compass:
    """Heading (rad, from north) with white noise: a magnetometer after calibration, or mocap yaw."""

    def __init__(self, world: Quadrotor, noise: SensorNoise, seed: int | None) -> None:
        self.world = world
        self.noise = noise
        self.src = NoiseSource(seed, 1)
        self.heading = 0.0
        self.fresh = False

    def periodic(self) -> None:
        x = self.world.x
        self.heading = quat_yaw(x[QW], x[QX], x[QY], x[QZ]) + self.noise.heading * self.src.next()[0]
        self.fresh = True


PROFILES: dict[str, SensorNoise] = {
    # seed 000's indoor flight: motion capture (about 1 cm), no velocity (modules.yaml: indoor -> mocap)
    "indoor": SensorNoise(pos_latency_s=0.01, pos_h=0.01, pos_v=0.01, pos_walk=0.0, vel=0.0, baro=0.05,
                          heading=0.005),
    # outdoor GPS-grade: 0.1 s latency, metre-level correlated error (modules.yaml: outdoor -> gps)
    "outdoor": SensorNoise(pos_latency_s=0.1, pos_h=0.15, pos_v=0.25, pos_walk=0.5, vel=0.08, baro=0.1,
                           heading=0.01),
    # no noise at all, for debugging and exact tests (modules.yaml: perfect -> gps)
    "perfect": SensorNoise(gyro=0.0, gyro_bias=0.0, accel=0.0, accel_bias=0.0, pos_latency_s=0.0, pos_h=0.0,
                           pos_v=0.0, vel=0.0, baro=0.0, heading=0.0),
}
