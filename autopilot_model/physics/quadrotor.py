"""Rigid-body quadrotor: 6 degrees of freedom, quaternion attitude, four motors with first-order lag.

The world the autopilot flies in. Integration is semi-implicit Euler with a fixed step (the main-loop
period, 2 ms by default). The inner step is a numba kernel on flat float64 arrays so that a whole
vehicle runs far faster than real time in lockstep.

Frames: NED world (z down, origin at home on the ground), FRD body. Quaternion (w, x, y, z) rotates
body to NED. Motors are numbered as ArduCopter's Quad X: 1 front-right CCW, 2 back-left CCW,
3 front-left CW, 4 back-right CW.

Forces: thrust T_i = k_t * w_i^2 along -z body; reaction torque +-k_q * w_i^2 (a CCW propeller
yaws the body clockwise, i.e. positive in NED); linear and quadratic drag on the air-relative velocity
(wind); rotational damping; gravity; ground contact (the ground at z = ``prm[P_GROUND]``, 0 unless
the terrain under the vehicle is raised (:mod:`autopilot_model.terrain`); it neither bounces nor
sinks: on contact the vertical velocity is removed, and while the thrust cannot lift the vehicle it
rests, level, with zero velocity).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from autopilot_model.quatmath import quat_integrate

GRAVITY = 9.80665

# indices into the state vector
PX, PY, PZ, VX, VY, VZ, QW, QX, QY, QZ, WX, WY, WZ = range(13)
STATE_SIZE = 13

# indices into the parameter vector
(P_MASS, P_IXX, P_IYY, P_IZZ, P_KT, P_KQ, P_TAU, P_WMAX, P_DRAG_LIN, P_DRAG_QUAD, P_DRAG_ROT,
 P_ARM, P_GROUND) = range(13)
PARAM_SIZE = 13

# Quad X geometry: angle of each arm from the nose (clockwise, degrees) and spin (+1 CCW, -1 CW)
MOTOR_ANGLES_DEG = (45.0, 225.0, 315.0, 135.0)
MOTOR_SPIN = (1.0, 1.0, -1.0, -1.0)


@njit(cache=True, fastmath=True)
def quad_step(x, w_mot, cmd, prm, wind, dt, mx, my, spin, out_f):  # pragma: no cover - numba
    """Advance the state ``x`` and motor speeds ``w_mot`` by ``dt``.

    ``cmd``: per-motor thrust command in [0, 1] (fraction of the maximum thrust; the motor speed
    target is sqrt(cmd) * w_max so steady thrust is linear in the command). ``wind``: NED wind
    velocity. ``mx``/``my``: motor x/y positions in the body frame. ``out_f`` receives the specific
    force in the body frame (what an accelerometer measures) and the ground-contact flag.
    Returns True when the vehicle touches the ground.
    """
    mass = prm[P_MASS]
    kt = prm[P_KT]
    kq = prm[P_KQ]
    a_mot = dt / (prm[P_TAU] + dt)
    wmax = prm[P_WMAX]
    thrust = 0.0
    tx = 0.0
    ty = 0.0
    tz = 0.0
    for i in range(4):
        c = cmd[i]
        if c < 0.0:
            c = 0.0
        elif c > 1.0:
            c = 1.0
        wt = math.sqrt(c) * wmax
        w_mot[i] += (wt - w_mot[i]) * a_mot
        t_i = kt * w_mot[i] * w_mot[i]
        thrust += t_i
        tx += -my[i] * t_i
        ty += mx[i] * t_i
        tz += spin[i] * kq * w_mot[i] * w_mot[i]

    qw = x[QW]
    qx = x[QX]
    qy = x[QY]
    qz = x[QZ]
    # rotation matrix body->NED, third column = body z axis in NED
    r02 = 2.0 * (qx * qz + qw * qy)
    r12 = 2.0 * (qy * qz - qw * qx)
    r22 = 1.0 - 2.0 * (qx * qx + qy * qy)
    r00 = 1.0 - 2.0 * (qy * qy + qz * qz)
    r01 = 2.0 * (qx * qy - qw * qz)
    r10 = 2.0 * (qx * qy + qw * qz)
    r11 = 1.0 - 2.0 * (qx * qx + qz * qz)
    r20 = 2.0 * (qx * qz - qw * qy)
    r21 = 2.0 * (qy * qz + qw * qx)

    # air-relative velocity and drag
    ax_ = x[VX] - wind[0]
    ay_ = x[VY] - wind[1]
    az_ = x[VZ] - wind[2]
    sp = math.sqrt(ax_ * ax_ + ay_ * ay_ + az_ * az_)
    cl = prm[P_DRAG_LIN]
    cqd = prm[P_DRAG_QUAD]
    fdx = -(cl + cqd * sp) * ax_
    fdy = -(cl + cqd * sp) * ay_
    fdz = -(cl + cqd * sp) * az_

    # world acceleration
    accx = (-thrust * r02 + fdx) / mass
    accy = (-thrust * r12 + fdy) / mass
    accz = (-thrust * r22 + fdz) / mass + 9.80665

    # rigid body rotation (Euler's equations), rotational damping
    ixx = prm[P_IXX]
    iyy = prm[P_IYY]
    izz = prm[P_IZZ]
    wx = x[WX]
    wy = x[WY]
    wz = x[WZ]
    dr = prm[P_DRAG_ROT]
    dwx = (tx - dr * wx - (izz - iyy) * wy * wz) / ixx
    dwy = (ty - dr * wy - (ixx - izz) * wx * wz) / iyy
    dwz = (tz - dr * wz - (iyy - ixx) * wx * wy) / izz

    # semi-implicit Euler
    vx = x[VX] + accx * dt
    vy = x[VY] + accy * dt
    vz = x[VZ] + accz * dt
    pz = x[PZ] + vz * dt
    wx += dwx * dt
    wy += dwy * dt
    wz += dwz * dt

    ground = False
    ground_d = prm[P_GROUND]  # the ground's down coordinate under the vehicle (terrain)
    if pz >= ground_d and vz >= 0.0:
        # ground contact: no sinking, no bounce; resting while thrust cannot lift
        ground = True
        pz = ground_d
        vz = 0.0
        accz = 0.0
        if thrust <= mass * 9.80665 * r22:
            vx = 0.0
            vy = 0.0
            accx = 0.0
            accy = 0.0
            wx = 0.0
            wy = 0.0
            wz = 0.0
            # settle level, keeping the heading
            yaw = math.atan2(r10, r00)
            qw = math.cos(0.5 * yaw)
            qx = 0.0
            qy = 0.0
            qz = math.sin(0.5 * yaw)
    x[PX] += vx * dt
    x[PY] += vy * dt
    x[PZ] = pz
    x[VX] = vx
    x[VY] = vy
    x[VZ] = vz

    x[QW], x[QX], x[QY], x[QZ] = quat_integrate(qw, qx, qy, qz, wx, wy, wz, dt)
    x[WX] = wx
    x[WY] = wy
    x[WZ] = wz

    # specific force in body = R^T (acc - g)
    sfx = accx
    sfy = accy
    sfz = accz - 9.80665
    out_f[0] = r00 * sfx + r10 * sfy + r20 * sfz
    out_f[1] = r01 * sfx + r11 * sfy + r21 * sfz
    out_f[2] = r02 * sfx + r12 * sfy + r22 * sfz
    out_f[3] = 1.0 if ground else 0.0
    out_f[4] = accx
    out_f[5] = accy
    out_f[6] = accz
    return ground


class Quadrotor:
    """The simulated airframe (the 'world' half of SITL); stepped once per main-loop iteration.

    ``x`` holds the true state, ``w_mot`` the motor speeds (rad/s), ``cmd`` the motor commands
    written by the actuators module, ``wind`` the current NED wind (written by :class:`Wind`).
    """

    def __init__(self, mass: float, inertia: tuple[float, float, float], arm: float, k_t: float,
                 k_q: float, motor_tau: float, w_max: float, drag_lin: float, drag_quad: float,
                 drag_rot: float) -> None:
        self.prm = np.zeros(PARAM_SIZE)
        self.prm[P_MASS] = mass
        self.prm[P_IXX], self.prm[P_IYY], self.prm[P_IZZ] = inertia
        self.prm[P_KT] = k_t
        self.prm[P_KQ] = k_q
        self.prm[P_TAU] = motor_tau
        self.prm[P_WMAX] = w_max
        self.prm[P_DRAG_LIN] = drag_lin
        self.prm[P_DRAG_QUAD] = drag_quad
        self.prm[P_DRAG_ROT] = drag_rot
        self.prm[P_ARM] = arm
        ang = np.radians(np.array(MOTOR_ANGLES_DEG))
        self.mx = arm * np.cos(ang)
        self.my = arm * np.sin(ang)
        self.spin = np.array(MOTOR_SPIN)
        self.x = np.zeros(STATE_SIZE)
        self.x[QW] = 1.0
        self.w_mot = np.zeros(4)
        self.cmd = np.zeros(4)
        self.wind = np.zeros(3)
        self.out = np.zeros(7)  # specific force body (3), on-ground flag, world acceleration (3)
        self.on_ground = True
        self.time_s = 0.0

    @property
    def max_thrust_per_motor(self) -> float:
        return float(self.prm[P_KT] * self.prm[P_WMAX] ** 2)

    @property
    def hover_command(self) -> float:
        """Motor command that holds the vehicle in hover (thrust linear in the command)."""
        return float(self.prm[P_MASS] * GRAVITY / (4.0 * self.max_thrust_per_motor))

    def place(self, north: float = 0.0, east: float = 0.0, down: float = 0.0, yaw: float = 0.0) -> None:
        """Put the vehicle at rest at a position with a heading."""
        self.x[:] = 0.0
        self.x[PX], self.x[PY], self.x[PZ] = north, east, down
        self.x[QW] = math.cos(0.5 * yaw)
        self.x[QZ] = math.sin(0.5 * yaw)
        self.w_mot[:] = 0.0
        self.cmd[:] = 0.0

    def step(self, dt: float) -> None:
        self.on_ground = quad_step(self.x, self.w_mot, self.cmd, self.prm, self.wind, dt, self.mx, self.my,
                                   self.spin, self.out)
        self.time_s += dt

    def electrical_power(self) -> float:
        """Shaft power of the four motors (W): sum of k_q * w^3."""
        w = self.w_mot
        return float(self.prm[P_KQ] * (w[0] ** 3 + w[1] ** 3 + w[2] ** 3 + w[3] ** 3))

    # --- read-outs for tests and telemetry ---------------------------------------------------------
    @property
    def position(self) -> tuple[float, float, float]:
        return (float(self.x[PX]), float(self.x[PY]), float(self.x[PZ]))

    @property
    def velocity(self) -> tuple[float, float, float]:
        return (float(self.x[VX]), float(self.x[VY]), float(self.x[VZ]))

    @property
    def quaternion(self) -> tuple[float, float, float, float]:
        return (float(self.x[QW]), float(self.x[QX]), float(self.x[QY]), float(self.x[QZ]))

    @property
    def rates(self) -> tuple[float, float, float]:
        return (float(self.x[WX]), float(self.x[WY]), float(self.x[WZ]))
