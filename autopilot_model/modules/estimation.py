"""State estimation (estimation task group): a velocity-aided complementary filter (INS/AHRS).

What the controllers use is this estimate, not the truth (a switch, ``use_truth``, passes the truth
through for debugging). Structure, as in small autopilots' INS/AHRS pair (seed 002 Fig. 2):

* Prediction at the main-loop rate: the attitude integrates the gyro minus its estimated bias; the
  position and velocity integrate the accelerometer rotated to NED plus gravity, minus an estimated
  world-frame acceleration bias.
* Position correction (GPS or motion capture, whichever module the resolver loaded, at the rate of its
  function in the schedule, delayed by its latency): the innovation
  against the *delayed* estimate drives a third-order observer (position, velocity, acceleration bias;
  triple pole at ``pos_bw`` rad/s). GPS velocity, when given, corrects the velocity.
* Tilt correction from the same innovation (velocity-aided AHRS): a tilt error delta makes the predicted
  horizontal acceleration wrong by g*delta, so the velocity correction dv tells the tilt error; the
  attitude is rotated by k_tilt * (dv x z) and the gyro bias integrates it.
* Heading correction from the compass (or the motion-capture yaw); gravity alignment from the
  accelerometer only while resting on the ground (where it is exact).
* Altitude from the barometer is blended when the position source is GPS.

The 500 Hz prediction is a numba kernel; the corrections run at the sensors' (lower) rates, their periods
the steps of the sensors' functions in the schedule (:meth:`Estimator.set_periods`).

Output (seed 002 Sec. 3.1): ``est`` is the filter's working state. What the rest of the autopilot reads
is the state interface, whose vector the finite-check kernel writes (``out``) after every update that
passed the check; the vehicle then publishes it (``StateInterface.publish``).

Health, as ArduPilot's EKF reports it to ``Copter::ekf_check``:

* Divergence: the kernels are compiled with fastmath, which lets the compiler assume that no value is
  NaN or infinite, so a finite-value test inside them can be folded to "true". The test is a separate
  kernel compiled *without* fastmath (:func:`ins_state_finite`), run on the stored state after each
  update. A non-finite state is a filter fault: the last finite state is restored (the biases reset), so
  nothing non-finite is ever published, and the position is not trusted for ``RECONVERGE_S``.
* Consistency: each position sample's innovation is tested against a gate, as EKF3's innovation
  consistency test (EK3_POS_I_GATE): ``pos_test_ratio`` = |innovation|^2 / gate^2; a sample with a
  ratio above 1, or with a non-finite value, is rejected (not fused). ``pos_variance`` is its square
  root, the figure ArduPilot's ``get_variances`` reports and FS_EKF_THRESH is compared with.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numba import njit

from autopilot_model.modules.sensors import Barometer, Compass, Imu, PositionSensor
from autopilot_model.physics.quadrotor import Quadrotor
from autopilot_model.quatmath import body_to_ned, ned_to_body, quat_integrate, quat_yaw, rotate_world

GRAVITY = 9.80665
log = logging.getLogger(__name__)


HIST = 256  # samples of estimate history kept for latency compensation (0.5 s at 500 Hz)
RECONVERGE_S = 3.0
"""After a filter fault the position is not trusted this long (a reset EKF's variances start large)."""


@njit(cache=True)  # NOT fastmath: under fastmath the compiler may assume finite values and drop the test
def ins_state_finite(est, acc, gbias, abias, good, out=None):  # pragma: no cover - numba
    """True if the estimate, its acceleration and biases are all finite; then ``good`` <- ``est`` and,
    if given, ``out`` <- ``[est(13), acc(3)]`` (the state interface's vector: the publication rides on
    the check, so only a checked estimate is ever published and publishing costs no extra call)."""
    for k in range(est.shape[0]):
        if not math.isfinite(est[k]):
            return False
    for k in range(3):
        if not (math.isfinite(acc[k]) and math.isfinite(gbias[k]) and math.isfinite(abias[k])):
            return False
    for k in range(est.shape[0]):
        good[k] = est[k]
    if out is not None:
        for k in range(13):
            out[k] = est[k]
        for k in range(3):
            out[13 + k] = acc[k]
    return True


@njit(cache=True, fastmath=True)
def ins_predict(est, gyro, accel, gbias, abias, dt, acc_w, hist, hidx, now):  # pragma: no cover - numba
    """est = [p(3), v(3), q(4), w(3)]; integrates one IMU sample; writes NED acceleration to acc_w and
    appends (now, p, v) to the ring ``hist`` at ``hidx[0]``. (No finite test here: see the module doc.)"""
    wx = gyro[0] - gbias[0]
    wy = gyro[1] - gbias[1]
    wz = gyro[2] - gbias[2]
    qw, qx, qy, qz = quat_integrate(est[6], est[7], est[8], est[9], wx, wy, wz, dt)
    est[6] = qw
    est[7] = qx
    est[8] = qy
    est[9] = qz
    est[10] = wx
    est[11] = wy
    est[12] = wz
    ax, ay, az = body_to_ned(qw, qx, qy, qz, accel[0], accel[1], accel[2])
    ax -= abias[0]
    ay -= abias[1]
    az += 9.80665 - abias[2]
    acc_w[0] = ax
    acc_w[1] = ay
    acc_w[2] = az
    est[3] += ax * dt
    est[4] += ay * dt
    est[5] += az * dt
    est[0] += est[3] * dt
    est[1] += est[4] * dt
    est[2] += est[5] * dt
    i = hidx[0]
    hist[i, 0] = now
    for k in range(6):
        hist[i, 1 + k] = est[k]
    hidx[0] = (i + 1) % hist.shape[0]


@njit(cache=True, fastmath=True)
def ins_correct_position(est, abias, gbias, hist, hidx, sample, sample_time, gains, dv):  # pragma: no cover
    """Third-order observer update from a delayed position (and velocity) sample; see the module doc.

    ``gains`` = [k1, k2, k3, kv (0 = no velocity), baro_weight, k_tilt, k_gbias, airborne, 1/gate^2].
    The innovation is taken against the estimate at ``sample_time`` (from the history ring) and the
    correction applied to the current estimate. ``dv`` receives the velocity correction. Returns the
    innovation test ratio |innovation|^2 / gate^2; above 1 the sample is rejected and nothing changes
    (the caller passes finite samples only, so the comparison is sound under fastmath)."""
    n = hist.shape[0]
    j = (hidx[0] - 1) % n
    best = j
    for _ in range(n):
        if hist[j, 0] <= sample_time + 1e-9:
            best = j
            break
        best = j
        j = (j - 1) % n
    ratio = 0.0
    for k in range(3):
        d = sample[k] - hist[best, 1 + k]
        ratio += d * d
    ratio *= gains[8]
    if ratio > 1.0:
        return ratio
    k1 = gains[0]
    k2 = gains[1]
    k3 = gains[2]
    kv = gains[3]
    bw = gains[4]
    for k in range(3):
        innov = sample[k] - hist[best, 1 + k]
        if k == 2 and bw > 0.0:
            innov *= 1.0 - bw
        est[k] += k1 * innov
        est[3 + k] += k2 * innov
        dv[k] = k2 * innov
        abias[k] -= k3 * innov
        if kv > 0.0:
            iv = sample[3 + k] - hist[best, 4 + k]
            est[3 + k] += kv * iv
            dv[k] += kv * iv
        if abias[k] > 2.0:
            abias[k] = 2.0
        elif abias[k] < -2.0:
            abias[k] = -2.0
    if gains[7] > 0.0:
        # velocity-aided tilt: rotate by c = k_tilt (dv x z) in the world frame, gyro bias integrates it
        cx = gains[5] * dv[1]
        cy = -gains[5] * dv[0]
        ins_rotate_world(est, gbias, cx, cy, 0.0, gains[6])
    return ratio


@njit(cache=True, fastmath=True)
def ins_align_gravity(est, accel, k):  # pragma: no cover - numba
    """Mahony's accelerometer term (e = f x v, body frame), used only at rest on the ground."""
    n = math.sqrt(accel[0] * accel[0] + accel[1] * accel[1] + accel[2] * accel[2])
    if n < 1e-3:
        return
    fx = accel[0] / n
    fy = accel[1] / n
    fz = accel[2] / n
    qw = est[6]
    qx = est[7]
    qy = est[8]
    qz = est[9]
    # v = R^T (0, 0, -1): the expected direction of the measured specific force
    vx, vy, vz = ned_to_body(qw, qx, qy, qz, 0.0, 0.0, -1.0)
    ex = fy * vz - fz * vy
    ey = fz * vx - fx * vz
    hx = 0.5 * k * ex
    hy = 0.5 * k * ey
    nw = qw - qx * hx - qy * hy
    nx = qx + qw * hx - qz * hy
    ny = qy + qw * hy + qz * hx
    nz = qz + qx * hy - qy * hx
    m = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    est[6] = nw * m
    est[7] = nx * m
    est[8] = ny * m
    est[9] = nz * m


@njit(cache=True, fastmath=True)
def ins_rotate_world(est, gbias, cx, cy, cz, k_gbias):  # pragma: no cover - numba
    """Correct the attitude by the small NED-frame rotation c; the gyro bias integrates it (body frame)."""
    qw, qx, qy, qz = rotate_world(est[6], est[7], est[8], est[9], cx, cy, cz)
    est[6] = qw
    est[7] = qx
    est[8] = qy
    est[9] = qz
    bx, by, bz = ned_to_body(qw, qx, qy, qz, cx, cy, cz)
    gbias[0] -= k_gbias * bx
    gbias[1] -= k_gbias * by
    gbias[2] -= k_gbias * bz


class Estimator:
    """INS/AHRS producing ``est`` = [p(3), v(3), q(4), body rates(3)] and ``acc`` (NED acceleration)."""

    def __init__(self, imu: Imu, pos: PositionSensor, baro: Barometer, compass: Compass, dt: float,
                 world: Quadrotor | None = None, use_truth: bool = False,
                 out: np.ndarray | None = None) -> None:
        self.imu = imu
        self.pos = pos
        self.baro = baro
        self.compass = compass
        self.dt = dt
        self.world = world
        self.use_truth = use_truth
        self.est = np.zeros(13)
        self.est[6] = 1.0
        self.acc = np.zeros(3)
        self.out = np.zeros(16) if out is None else out
        """The published estimate ``[est(13), acc(3)]``: written after every update that passed the
        finite check (the vehicle passes the state interface's :meth:`~autopilot_model.state.
        StateInterface.estimate_buffer`, so the estimate lands in the blackboard with no copy in
        Python). ``est`` is the filter's working state and is never read by the control chain."""
        self.gbias = np.zeros(3)
        self.abias = np.zeros(3)
        self.on_ground = True
        self.vel_bw = 2.0
        self.k_gbias = 0.05
        self.k_yaw = 1.5                        # 1/s
        self.k_grav = 2.0                       # 1/s, only on the ground
        self.baro_bw = 1.0  # rad/s, height observer poles on the barometer
        self.hist = np.zeros((HIST, 7))
        self.hidx = np.zeros(1, dtype=np.int64)
        self._sample = np.zeros(6)
        self._dv = np.zeros(3)
        self._gains = np.zeros(9)
        self.pos_test_ratio = 0.0
        """Innovation test ratio of the last position sample (> 1: rejected; inf: not finite)."""
        self.rejected = 0
        """Position samples rejected (gate or non-finite), in total."""
        self.diverged = 0
        """Filter faults (a non-finite state), in total."""
        self._good = np.zeros(13)
        self._good[6] = 1.0
        self._fault_s = -math.inf
        self.initialised = False
        self.time_s = 0.0
        # periods (s) of the position, barometer and compass samples the corrections consume: the
        # periods of their functions in the schedule, set by the vehicle (Vehicle.start)
        self.pos_dt = math.nan
        self.baro_dt = math.nan
        self.heading_dt = math.nan
        self.set_position_source("gps")

    def set_position_source(self, module: str) -> None:
        """Tune the position observer for the position source the module resolver loaded (the module
        providing ``@position_source``: ``gps`` or ``mocap``, seed 002 Sec. 3.2)."""
        mocap = module == "mocap"
        self.position_source = module
        # rad/s, position observer poles: GPS position has a metre-level correlated error, so velocity
        # comes mostly from GPS velocity (vel_bw) and the position corrects slowly, like an EKF's weights
        self.pos_bw = 6.0 if mocap else 0.6
        self.k_tilt = 0.25 if mocap else 0.08   # rad per (m/s) of velocity correction
        # height: the barometer is the primary source outdoors (ArduPilot's EK3_ALT_SOURCE default);
        # GPS height is weighted (1 - baro_weight) in the position correction
        self.baro_weight = 0.0 if mocap else 0.9
        # innovation gate (m): about five standard deviations of the innovation, as EK3_POS_I_GATE (500
        # = 5 sigma); GPS innovations carry its metre-level correlated error, motion capture's are mm
        self.pos_gate_m = 0.5 if mocap else 5.0

    def set_periods(self, pos_dt: float, baro_dt: float, heading_dt: float) -> None:
        """The periods (s) of the position, barometer and compass samples: their functions' steps in the
        schedule (main loop period times prescaler). ``baro_dt`` / ``heading_dt`` may be NaN when that
        sensor is not scheduled (its samples never arrive, its correction never runs)."""
        for name, value, optional in (("pos_dt", pos_dt, False), ("baro_dt", baro_dt, True),
                                      ("heading_dt", heading_dt, True)):
            if optional and math.isnan(value):
                continue
            if not (value > 0.0 and math.isfinite(value)):
                raise ValueError(f"estimator {name} must be a positive period in seconds, got {value!r}")
        self.pos_dt, self.baro_dt, self.heading_dt = float(pos_dt), float(baro_dt), float(heading_dt)

    # -- health (what ArduPilot's EKF reports to Copter::ekf_check and the AHRS health bit)
    @property
    def position_ok(self) -> bool:
        """ArduCopter's ``ekf_position_ok``: initialised, and not re-converging after a filter fault."""
        if self.use_truth:
            return self.initialised and self.pos.sample is not None
        return self.initialised and self.time_s - self._fault_s >= RECONVERGE_S

    @property
    def pos_variance(self) -> float:
        """Normalised position innovation (sqrt of the test ratio), what FS_EKF_THRESH is compared with."""
        return math.sqrt(self.pos_test_ratio)

    @property
    def healthy(self) -> bool:
        """Usable for flight (pre-arm check, SYS_STATUS AHRS bit): the position is trusted and the last
        position sample passed its consistency test."""
        return self.position_ok and self.pos_test_ratio <= 1.0

    # -- estimation periodic (main-loop rate)
    def periodic(self, now_s: float) -> None:
        self.time_s = now_s
        if self.use_truth and self.world is not None:
            x = self.world.x
            self.est[:] = x
            self.acc[:] = self.world.out[4:7]
            self.initialised = True
            self._output()
            return
        if not self.initialised:
            self._initialise()
            if not self.initialised:
                return
        ins_predict(self.est, self.imu.gyro, self.imu.accel, self.gbias, self.abias, self.dt, self.acc,
                    self.hist, self.hidx, now_s)
        if self.pos.fresh:
            self.pos.fresh = False
            self._correct_position()
        if self.compass.fresh:
            self.compass.fresh = False
            self._correct_heading()
        if self.baro.fresh:
            self.baro.fresh = False
            self._correct_baro()
        if self.on_ground:
            self._align_gravity()
        if not ins_state_finite(self.est, self.acc, self.gbias, self.abias, self._good, self.out):
            self._diverged()

    def _initialise(self) -> None:
        """Start from the first position fix, level, on the compass heading."""
        if self.pos.sample is None or not self.compass.fresh:
            return
        if math.isnan(self.pos_dt):
            raise RuntimeError("the estimator's sensor periods are not set: Vehicle.start() sets them from "
                               "the schedule (Estimator.set_periods)")
        s = self.pos.sample
        self.est[:] = 0.0
        self.est[0], self.est[1], self.est[2] = s[0], s[1], s[2]
        yaw = self.compass.heading
        self.est[6] = math.cos(0.5 * yaw)
        self.est[9] = math.sin(0.5 * yaw)
        self.pos.fresh = False
        self.hist[:, 0] = self.time_s
        self.hist[:, 1:7] = self.est[0:6]
        self._good[:] = self.est
        self.initialised = True

    def _diverged(self) -> None:
        """A filter fault (non-finite state): restore the last finite state, reset the biases and the
        latency history, and distrust the position for ``RECONVERGE_S`` (ArduPilot's EKF resets itself on
        a fault and reports itself unhealthy while its variances are large). Nothing non-finite is ever
        published: the check kernel writes ``out`` (the state interface's vector) only for a finite state,
        and the restored state is written to it here."""
        self.diverged += 1
        log.error("estimator diverged (%d): last finite state restored", self.diverged)
        self.est[:] = self._good
        self.acc[:] = 0.0
        self.gbias[:] = 0.0
        self.abias[:] = 0.0
        self.hist[:, 0] = self.time_s
        self.hist[:, 1:7] = self.est[0:6]
        self._fault_s = self.time_s
        self._output()

    def _output(self) -> None:
        """Write the estimate to ``out`` outside the check kernel (the truth switch, a restored state)."""
        self.out[0:13] = self.est
        self.out[13:16] = self.acc

    def _correct_position(self) -> None:
        s = self.pos.sample
        if s is None:
            return
        if not all(math.isfinite(x) for x in s):
            self.pos_test_ratio = math.inf
            self.rejected += 1
            return
        T = self.pos_dt
        w = self.pos_bw
        g = self._gains
        g[0] = min(3.0 * w * T, 0.9)
        g[1] = 3.0 * w * w * T
        g[2] = w * w * w * T
        g[3] = min(self.vel_bw * T, 0.8) if (self.pos.is_gps and self.pos.noise.vel > 0) else 0.0
        g[4] = self.baro_weight
        g[5] = self.k_tilt
        g[6] = self.k_gbias
        g[7] = 0.0 if self.on_ground else 1.0
        g[8] = 1.0 / (self.pos_gate_m * self.pos_gate_m)
        self._sample[:] = s
        self.pos_test_ratio = ins_correct_position(self.est, self.abias, self.gbias, self.hist, self.hidx,
                                                   self._sample, self.pos.sample_time, g, self._dv)
        if self.pos_test_ratio > 1.0:
            self.rejected += 1

    def _correct_heading(self) -> None:
        e = self.est
        err = self.compass.heading - quat_yaw(e[6], e[7], e[8], e[9])
        err = (err + math.pi) % (2.0 * math.pi) - math.pi
        rate = self.heading_dt
        ins_rotate_world(e, self.gbias, 0.0, 0.0, self.k_yaw * err * rate, self.k_gbias * 0.2)

    def _correct_baro(self) -> None:
        if self.baro_weight <= 0:
            return
        innov = (-self.baro.alt - self.est[2]) * self.baro_weight
        T = self.baro_dt
        w = self.baro_bw
        self.est[2] += min(3.0 * w * T, 0.5) * innov
        self.est[5] += 3.0 * w * w * T * innov
        self.abias[2] -= w * w * w * T * innov

    def _align_gravity(self) -> None:
        """On the ground the accelerometer measures gravity alone: pull roll and pitch to it."""
        ins_align_gravity(self.est, self.imu.accel, self.k_grav * self.dt)
