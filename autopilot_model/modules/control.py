"""Cascaded PID control (seed 000 Fig. 6c, Sec. IV-D; seed 002 Fig. 2 'commands' array).

position -> velocity -> acceleration -> attitude -> body rate -> commands [thrust, torque x, y, z].

* Position loop: v_cmd = v_d + K_pos (p_d - p), the correction limited to ``vel_corr_max``.
* Velocity loop (PID with anti-windup): a_cmd = a_d + K_vp (v_cmd - v) + K_vi * integral + K_vd * d/dt.
  Feed-forward from P_d = [p_d, v_d, a_d] is what lets the vehicle follow the setpoint generator tightly.
  Horizontally the error is low-pass filtered first, as ArduCopter's ``AC_PID_2D::update_all`` does for
  ``PSC_VELXY_``: the error e_f += (e - e_f) alpha(PSC_VELXY_FLTE) feeds P and I, its derivative
  (e_f - e_f,prev) / dt, filtered again with alpha(PSC_VELXY_FLTD), feeds D, with ArduPilot's
  ``calc_lowpass_alpha_dt``: alpha = dt / (dt + 1 / (2 pi f)), 1 (no filter) for f = 0. Both default to
  5 Hz as in ArduCopter (POSCONTROL_VEL_XY_FILT_HZ, POSCONTROL_VEL_XY_FILT_D_HZ). After a reset the filter
  starts at the raw error and a zero derivative, as ArduPilot's ``reset_filter``; 0 Hz on both gives the
  unfiltered loop. Measured by ``bench/bench_hover.py``: the filter does not lower the
  true speed in a GPS hover (about 0.32 m/s median without, 0.36 with), whose power lies below 1 Hz,
  where the position loop follows the wander of the GPS-aided position estimate; see the README.
* Acceleration to attitude: the specific force f = a_cmd - g gives the desired body z axis
  (-f/|f|) and the collective thrust m * (-f . z_body); the tilt is limited to ``max_tilt`` by
  shrinking the horizontal part of f (and the horizontal integrator stops winding up).
* Attitude loop: quaternion error -> body-rate command (P), plus the yaw-rate feed-forward.
* Rate loop (PID): angular acceleration -> torque through the inertia (plus the gyroscopic term).

The kernel is numba-compiled; :class:`CascadedController` reads the state interface (seed 002 Sec. 3.1,
Fig. 2: the vehicle's control function passes :attr:`autopilot_model.state.StateInterface.vector`, the
read-only view of the blackboard the estimator publishes into, never the estimator's own array) and the
setpoint generator's P_d, and writes the commands that the mixer (:mod:`.actuators`) turns into motor
outputs. Gains are parameters (ArduCopter names, SI units: see :data:`GAIN_PARAMS`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from autopilot_model.params import ParamStore

# gain vector layout
(G_POS_XY_P, G_POS_Z_P, G_VEL_XY_P, G_VEL_XY_I, G_VEL_XY_D, G_VEL_Z_P, G_VEL_Z_I, G_VEL_Z_D,
 G_ANG_RP_P, G_ANG_Y_P, G_RAT_RP_P, G_RAT_RP_I, G_RAT_RP_D, G_RAT_Y_P, G_RAT_Y_I, G_RAT_Y_D,
 G_MAX_TILT, G_MAX_RATE_RP, G_MAX_RATE_Y, G_VEL_IMAX, G_RAT_IMAX, G_MASS, G_IXX, G_IYY, G_IZZ,
 G_THRUST_MAX, G_VEL_CORR_MAX, G_ACC_Z_UP_MAX, G_VEL_XY_FLTE, G_VEL_XY_FLTD) = range(30)
GAIN_SIZE = 30
# horizontal velocity filter state layout: filtered error x, y; filtered derivative x, y; reset flag
F_EX, F_EY, F_DX, F_DY, F_RESET = range(5)
FILT_SIZE = 5

# (parameter name, gain index, default, min, max, scale from parameter to SI, doc)
GAIN_PARAMS: tuple[tuple[str, int, float, float, float, float, str], ...] = (
    ("PSC_POSXY_P", G_POS_XY_P, 3.0, 0.0, 10.0, 1.0, "horizontal position P (1/s)"),
    ("PSC_POSZ_P", G_POS_Z_P, 2.0, 0.0, 10.0, 1.0, "vertical position P (1/s)"),
    ("PSC_VELXY_P", G_VEL_XY_P, 6.0, 0.0, 20.0, 1.0, "horizontal velocity P (1/s)"),
    ("PSC_VELXY_I", G_VEL_XY_I, 4.0, 0.0, 20.0, 1.0, "horizontal velocity I (1/s^2)"),
    ("PSC_VELXY_D", G_VEL_XY_D, 0.0, 0.0, 5.0, 1.0, "horizontal velocity D (-)"),
    ("PSC_VELXY_FLTE", G_VEL_XY_FLTE, 5.0, 0.0, 100.0, 1.0,
     "horizontal velocity error filter for P and I (Hz, 0 = off)"),
    ("PSC_VELXY_FLTD", G_VEL_XY_FLTD, 5.0, 0.0, 100.0, 1.0,
     "horizontal velocity error derivative filter for D (Hz, 0 = off)"),
    ("PSC_VELZ_P", G_VEL_Z_P, 5.0, 0.0, 20.0, 1.0, "vertical velocity P (1/s)"),
    ("PSC_VELZ_I", G_VEL_Z_I, 3.0, 0.0, 20.0, 1.0, "vertical velocity I (1/s^2)"),
    ("PSC_VELZ_D", G_VEL_Z_D, 0.0, 0.0, 5.0, 1.0, "vertical velocity D (-)"),
    ("ATC_ANG_RLL_P", G_ANG_RP_P, 12.0, 0.0, 30.0, 1.0, "roll/pitch angle P (1/s)"),
    ("ATC_ANG_YAW_P", G_ANG_Y_P, 4.0, 0.0, 30.0, 1.0, "yaw angle P (1/s)"),
    ("ATC_RAT_RLL_P", G_RAT_RP_P, 35.0, 0.0, 200.0, 1.0, "roll/pitch rate P (1/s)"),
    ("ATC_RAT_RLL_I", G_RAT_RP_I, 20.0, 0.0, 500.0, 1.0, "roll/pitch rate I (1/s^2)"),
    ("ATC_RAT_RLL_D", G_RAT_RP_D, 0.4, 0.0, 5.0, 1.0, "roll/pitch rate D (-)"),
    ("ATC_RAT_YAW_P", G_RAT_Y_P, 12.0, 0.0, 200.0, 1.0, "yaw rate P (1/s)"),
    ("ATC_RAT_YAW_I", G_RAT_Y_I, 4.0, 0.0, 500.0, 1.0, "yaw rate I (1/s^2)"),
    ("ATC_RAT_YAW_D", G_RAT_Y_D, 0.0, 0.0, 5.0, 1.0, "yaw rate D (-)"),
    ("ANGLE_MAX", G_MAX_TILT, 3500.0, 1000.0, 8000.0, math.radians(0.01), "max lean angle (centidegrees)"),
    ("ATC_RATE_R_MAX", G_MAX_RATE_RP, 220.0, 10.0, 1080.0, math.radians(1.0), "max roll/pitch rate (deg/s)"),
    ("ATC_RATE_Y_MAX", G_MAX_RATE_Y, 90.0, 10.0, 1080.0, math.radians(1.0), "max yaw rate (deg/s)"),
    ("PSC_VELXY_IMAX", G_VEL_IMAX, 300.0, 0.0, 1000.0, 0.01, "velocity integrator limit (cm/s^2)"),
)


@njit(cache=True, fastmath=True)
def lowpass_alpha(dt, hz):  # pragma: no cover - numba
    """ArduPilot's ``calc_lowpass_alpha_dt``: the first-order low-pass weight for a step ``dt`` at ``hz``
    (1: no filtering when ``hz`` is 0)."""
    if hz <= 0.0:
        return 1.0
    rc = 1.0 / (2.0 * math.pi * hz)
    return dt / (dt + rc)


@njit(cache=True, fastmath=True)
def cascade_step(est, ref, g, integ, prev, filt, dt, out):  # pragma: no cover - numba
    """One control step. ``est`` = [p(3), v(3), q(4), w(3)], ``ref`` = [p_d(3), v_d(3), a_d(3), yaw_d,
    yaw_rate_d]. ``integ`` (6) and ``prev`` (6) hold integrator and previous-error state, ``filt``
    (:data:`FILT_SIZE`) the horizontal velocity error filter (``F_RESET`` 1: start it at the next step).
    ``out`` = [thrust (N), torque x, y, z (N m), desired q (4), a_cmd (3), saturated flag]."""
    # ---- position -> velocity
    vc = g[G_VEL_CORR_MAX]
    ex = ref[0] - est[0]
    ey = ref[1] - est[1]
    ez = ref[2] - est[2]
    cx = g[G_POS_XY_P] * ex
    cy = g[G_POS_XY_P] * ey
    ch = math.sqrt(cx * cx + cy * cy)
    if ch > vc:
        cx *= vc / ch
        cy *= vc / ch
    cz = g[G_POS_Z_P] * ez
    if cz > vc:
        cz = vc
    elif cz < -vc:
        cz = -vc
    vcx = ref[3] + cx
    vcy = ref[4] + cy
    vcz = ref[5] + cz
    # ---- velocity PID -> acceleration (horizontal: AC_PID_2D's filtered error and derivative)
    rvx = vcx - est[3]
    rvy = vcy - est[4]
    evz = vcz - est[5]
    if filt[F_RESET] != 0.0:
        filt[F_EX] = rvx
        filt[F_EY] = rvy
        filt[F_DX] = 0.0
        filt[F_DY] = 0.0
        filt[F_RESET] = 0.0
    else:
        ae = lowpass_alpha(dt, g[G_VEL_XY_FLTE])
        ad = lowpass_alpha(dt, g[G_VEL_XY_FLTD])
        lex = filt[F_EX]
        ley = filt[F_EY]
        filt[F_EX] = lex + (rvx - lex) * ae
        filt[F_EY] = ley + (rvy - ley) * ae
        filt[F_DX] += ((filt[F_EX] - lex) / dt - filt[F_DX]) * ad
        filt[F_DY] += ((filt[F_EY] - ley) / dt - filt[F_DY]) * ad
    evx = filt[F_EX]
    evy = filt[F_EY]
    imax = g[G_VEL_IMAX]
    axc = ref[6] + g[G_VEL_XY_P] * evx + integ[0] + g[G_VEL_XY_D] * filt[F_DX]
    ayc = ref[7] + g[G_VEL_XY_P] * evy + integ[1] + g[G_VEL_XY_D] * filt[F_DY]
    azc = ref[8] + g[G_VEL_Z_P] * evz + integ[2] + g[G_VEL_Z_D] * (evz - prev[2]) / dt
    prev[0] = evx
    prev[1] = evy
    prev[2] = evz
    # vertical acceleration limits: never command more than free fall, never more climb than set
    grav = 9.80665
    up_max = g[G_ACC_Z_UP_MAX]
    sat_z = False
    if azc > 0.8 * grav:
        azc = 0.8 * grav
        sat_z = True
    elif azc < -up_max:
        azc = -up_max
        sat_z = True
    fz = azc - grav  # specific force needed (NED), negative = up
    fx = axc
    fy = ayc
    # tilt limit: |f_h| <= |f_z| tan(max_tilt)
    fh = math.sqrt(fx * fx + fy * fy)
    fh_max = -fz * math.tan(g[G_MAX_TILT])
    sat_h = False
    if fh > fh_max:
        fx *= fh_max / fh
        fy *= fh_max / fh
        sat_h = True
    # integrators with anti-windup (conditional integration)
    ki = g[G_VEL_XY_I] * dt
    if not sat_h:
        integ[0] = min(max(integ[0] + ki * evx, -imax), imax)
        integ[1] = min(max(integ[1] + ki * evy, -imax), imax)
    if not sat_z:
        integ[2] = min(max(integ[2] + g[G_VEL_Z_I] * dt * evz, -imax), imax)

    # ---- acceleration -> desired attitude
    fn = math.sqrt(fx * fx + fy * fy + fz * fz)
    zbx = -fx / fn
    zby = -fy / fn
    zbz = -fz / fn
    yaw = ref[9]
    xcx = math.cos(yaw)
    xcy = math.sin(yaw)
    # y_b = z_b x x_c
    ybx = zby * 0.0 - zbz * xcy
    yby = zbz * xcx - zbx * 0.0
    ybz = zbx * xcy - zby * xcx
    yn = math.sqrt(ybx * ybx + yby * yby + ybz * ybz)
    ybx /= yn
    yby /= yn
    ybz /= yn
    # x_b = y_b x z_b
    xbx = yby * zbz - ybz * zby
    xby = ybz * zbx - ybx * zbz
    xbz = ybx * zby - yby * zbx
    # rotation matrix -> quaternion (columns x_b, y_b, z_b)
    tr = xbx + yby + zbz
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        dw = 0.25 * s
        dx = (ybz - zby) / s
        dy = (zbx - xbz) / s
        dz = (xby - ybx) / s
    elif xbx > yby and xbx > zbz:
        s = math.sqrt(1.0 + xbx - yby - zbz) * 2.0
        dw = (ybz - zby) / s
        dx = 0.25 * s
        dy = (ybx + xby) / s
        dz = (zbx + xbz) / s
    elif yby > zbz:
        s = math.sqrt(1.0 + yby - xbx - zbz) * 2.0
        dw = (zbx - xbz) / s
        dx = (ybx + xby) / s
        dy = 0.25 * s
        dz = (zby + ybz) / s
    else:
        s = math.sqrt(1.0 + zbz - xbx - yby) * 2.0
        dw = (xby - ybx) / s
        dx = (zbx + xbz) / s
        dy = (zby + ybz) / s
        dz = 0.25 * s

    qw = est[6]
    qx = est[7]
    qy = est[8]
    qz = est[9]
    # collective thrust: projection of the needed force on the current body z axis
    r02 = 2.0 * (qx * qz + qw * qy)
    r12 = 2.0 * (qy * qz - qw * qx)
    r22 = 1.0 - 2.0 * (qx * qx + qy * qy)
    thrust = -g[G_MASS] * (fx * r02 + fy * r12 + fz * r22)
    if thrust < 0.0:
        thrust = 0.0

    # ---- attitude error q_e = q^-1 (x) q_d
    ew = qw * dw + qx * dx + qy * dy + qz * dz
    exq = qw * dx - qx * dw - qy * dz + qz * dy
    eyq = qw * dy + qx * dz - qy * dw - qz * dx
    ezq = qw * dz - qx * dy + qy * dx - qz * dw
    if ew < 0.0:
        exq = -exq
        eyq = -eyq
        ezq = -ezq
    rmax = g[G_MAX_RATE_RP]
    ymax = g[G_MAX_RATE_Y]
    wcx = min(max(2.0 * g[G_ANG_RP_P] * exq, -rmax), rmax)
    wcy = min(max(2.0 * g[G_ANG_RP_P] * eyq, -rmax), rmax)
    wcz = min(max(2.0 * g[G_ANG_Y_P] * ezq + ref[10] * r22, -ymax), ymax)

    # ---- rate PID -> torque
    wx = est[10]
    wy = est[11]
    wz = est[12]
    erx = wcx - wx
    ery = wcy - wy
    erz = wcz - wz
    rimax = g[G_RAT_IMAX]
    integ[3] = min(max(integ[3] + g[G_RAT_RP_I] * dt * erx, -rimax), rimax)
    integ[4] = min(max(integ[4] + g[G_RAT_RP_I] * dt * ery, -rimax), rimax)
    integ[5] = min(max(integ[5] + g[G_RAT_Y_I] * dt * erz, -rimax), rimax)
    alx = g[G_RAT_RP_P] * erx + integ[3] + g[G_RAT_RP_D] * (erx - prev[3]) / dt
    aly = g[G_RAT_RP_P] * ery + integ[4] + g[G_RAT_RP_D] * (ery - prev[4]) / dt
    alz = g[G_RAT_Y_P] * erz + integ[5] + g[G_RAT_Y_D] * (erz - prev[5]) / dt
    prev[3] = erx
    prev[4] = ery
    prev[5] = erz
    ixx = g[G_IXX]
    iyy = g[G_IYY]
    izz = g[G_IZZ]
    out[0] = thrust
    out[1] = ixx * alx + (izz - iyy) * wy * wz
    out[2] = iyy * aly + (ixx - izz) * wx * wz
    out[3] = izz * alz + (iyy - ixx) * wx * wy
    out[4] = dw
    out[5] = dx
    out[6] = dy
    out[7] = dz
    out[8] = fx
    out[9] = fy
    out[10] = fz + grav
    out[11] = 1.0 if (sat_h or sat_z) else 0.0


class CascadedController:
    """The control task group's module: reads the state interface's vector and P_d, writes ``commands``.

    ``commands`` = [thrust N, torque x, y, z N m] is the seed-002 'commands array'; the actuators
    module mixes it. ``reset()`` clears integrators (on arming and while disarmed).
    """

    def __init__(self, params: ParamStore, mass: float, inertia: tuple[float, float, float],
                 thrust_max_total: float, dt: float) -> None:
        self.params = params
        self.dt = dt
        self.g = np.zeros(GAIN_SIZE)
        self.g[G_MASS] = mass
        self.g[G_IXX], self.g[G_IYY], self.g[G_IZZ] = inertia
        self.g[G_THRUST_MAX] = thrust_max_total
        self.g[G_VEL_CORR_MAX] = 3.0
        self.g[G_RAT_IMAX] = 20.0
        self.g[G_ACC_Z_UP_MAX] = min(0.9 * (thrust_max_total / mass - 9.80665), 15.0)
        for name, idx, default, lo, hi, scale, doc in GAIN_PARAMS:
            params.define(name, default, lo, hi, doc=doc)
            self.g[idx] = params.get(name) * scale
        params.subscribe("PSC_", self._on_param)
        params.subscribe("ATC_", self._on_param)
        params.subscribe("ANGLE_MAX", self._on_param)
        self._index = {name: (idx, scale) for name, idx, _d, _l, _h, scale, _doc in GAIN_PARAMS}
        self.ref = np.zeros(11)
        self.integ = np.zeros(6)
        self.prev = np.zeros(6)
        self.filt = np.zeros(FILT_SIZE)
        self.filt[F_RESET] = 1.0
        self.out = np.zeros(12)
        self.commands = self.out  # [thrust, tx, ty, tz] in out[0:4]
        self._clear = False
        self.reset()

    def _on_param(self, name: str, value: float) -> None:
        entry = self._index.get(name)
        if entry is not None:
            self.g[entry[0]] = value * entry[1]

    def reset(self) -> None:
        """Clear integrators and outputs (cheap when already clear: called every iteration disarmed)."""
        if self._clear:
            return
        self.integ[:] = 0.0
        self.prev[:] = 0.0
        self.filt[:] = 0.0
        self.filt[F_RESET] = 1.0
        self.out[:] = 0.0
        self.out[4] = 1.0
        self._clear = True

    def step(self, est: np.ndarray, p: tuple, v: tuple, a: tuple, yaw: float, yaw_rate: float) -> None:
        """One control step of ``dt`` (the schedule's step): ``est`` is the state vector
        ``[p(3), v(3), q(4), w(3), ...]`` (:attr:`autopilot_model.state.StateInterface.vector`), ``p``,
        ``v``, ``a``, ``yaw``, ``yaw_rate`` the setpoints P_d."""
        ref = self.ref
        ref[0], ref[1], ref[2] = p
        ref[3], ref[4], ref[5] = v
        ref[6], ref[7], ref[8] = a
        ref[9] = yaw
        ref[10] = yaw_rate
        self._clear = False
        cascade_step(est, ref, self.g, self.integ, self.prev, self.filt, self.dt, self.out)
