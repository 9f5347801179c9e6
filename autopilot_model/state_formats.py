"""Attitude format conversions of the state interface (seed 002 Sec. 3.1: "Euler angles, rotation matrix or
quaternion in the case of attitude representation"): pure math on float tuples, body -> NED, ZYX Euler.

Public (re-exported by :mod:`autopilot_model.state`); controllers and telemetry use them too.
"""

from __future__ import annotations

import math

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]


def quat_to_euler(q: Quat) -> Vec3:
    """Unit quaternion (w, x, y, z) -> Euler (roll, pitch, yaw), ZYX convention, radians."""
    w, x, y, z = q
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    sp = 2.0 * (w * y - z * x)
    pitch = math.asin(1.0 if sp > 1.0 else (-1.0 if sp < -1.0 else sp))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return (roll, pitch, yaw)


def euler_to_quat(e: Vec3) -> Quat:
    """Euler (roll, pitch, yaw), ZYX, radians -> unit quaternion (w, x, y, z) with w >= 0."""
    hr, hp, hy = 0.5 * e[0], 0.5 * e[1], 0.5 * e[2]
    cr, sr = math.cos(hr), math.sin(hr)
    cp, sp = math.cos(hp), math.sin(hp)
    cy, sy = math.cos(hy), math.sin(hy)
    w = cr * cp * cy + sr * sp * sy
    x = sr * cp * cy - cr * sp * sy
    y = cr * sp * cy + sr * cp * sy
    z = cr * cp * sy - sr * sp * cy
    if w < 0.0:
        return (-w, -x, -y, -z)
    return (w, x, y, z)


def quat_to_matrix(q: Quat) -> Mat3:
    """Unit quaternion (w, x, y, z) -> rotation matrix body -> NED (rows)."""
    w, x, y, z = q
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (
        (1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)),
        (2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)),
        (2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)),
    )


def matrix_to_quat(m: Mat3) -> Quat:
    """Rotation matrix body -> NED -> unit quaternion (w, x, y, z), w >= 0 (Shepperd's method)."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m
    tr = m00 + m11 + m22
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        w, x, y, z = 0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        w, x, y, z = (m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        w, x, y, z = (m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        w, x, y, z = (m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if w < 0.0:
        n = -n
    return (w / n, x / n, y / n, z / n)


def euler_to_matrix(e: Vec3) -> Mat3:
    """Euler (roll, pitch, yaw), ZYX, radians -> rotation matrix body -> NED: Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(e[0]), math.sin(e[0])
    cp, sp = math.cos(e[1]), math.sin(e[1])
    cy, sy = math.cos(e[2]), math.sin(e[2])
    return (
        (cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy),
        (cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy),
        (-sp, sr * cp, cr * cp),
    )


def matrix_to_euler(m: Mat3) -> Vec3:
    """Rotation matrix body -> NED -> Euler (roll, pitch, yaw), ZYX, radians."""
    s = -m[2][0]
    pitch = math.asin(1.0 if s > 1.0 else (-1.0 if s < -1.0 else s))
    return (math.atan2(m[2][1], m[2][2]), pitch, math.atan2(m[1][0], m[0][0]))
