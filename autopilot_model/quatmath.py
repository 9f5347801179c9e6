"""Quaternion helpers shared by the compiled kernels (physics, estimator, control).

Quaternions are (w, x, y, z) and rotate body to NED. These are numba functions that the kernels inline,
so each formula exists once.
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, fastmath=True, inline="always")
def quat_integrate(qw, qx, qy, qz, wx, wy, wz, dt):  # pragma: no cover - numba
    """q + 0.5 q (x) (0, w) dt, normalised: one step of body-rate integration."""
    hdt = 0.5 * dt
    nqw = qw + hdt * (-qx * wx - qy * wy - qz * wz)
    nqx = qx + hdt * (qw * wx + qy * wz - qz * wy)
    nqy = qy + hdt * (qw * wy - qx * wz + qz * wx)
    nqz = qz + hdt * (qw * wz + qx * wy - qy * wx)
    n = 1.0 / math.sqrt(nqw * nqw + nqx * nqx + nqy * nqy + nqz * nqz)
    return nqw * n, nqx * n, nqy * n, nqz * n


@njit(cache=True, fastmath=True, inline="always")
def body_to_ned(qw, qx, qy, qz, x, y, z):  # pragma: no cover - numba
    """R(q) (x, y, z): a body-frame vector in NED."""
    return (
        (1.0 - 2.0 * (qy * qy + qz * qz)) * x + 2.0 * (qx * qy - qw * qz) * y + 2.0 * (qx * qz + qw * qy) * z,
        2.0 * (qx * qy + qw * qz) * x + (1.0 - 2.0 * (qx * qx + qz * qz)) * y + 2.0 * (qy * qz - qw * qx) * z,
        2.0 * (qx * qz - qw * qy) * x + 2.0 * (qy * qz + qw * qx) * y + (1.0 - 2.0 * (qx * qx + qy * qy)) * z,
    )


@njit(cache=True, fastmath=True, inline="always")
def ned_to_body(qw, qx, qy, qz, x, y, z):  # pragma: no cover - numba
    """R(q)^T (x, y, z): an NED vector in the body frame."""
    return (
        (1.0 - 2.0 * (qy * qy + qz * qz)) * x + 2.0 * (qx * qy + qw * qz) * y + 2.0 * (qx * qz - qw * qy) * z,
        2.0 * (qx * qy - qw * qz) * x + (1.0 - 2.0 * (qx * qx + qz * qz)) * y + 2.0 * (qy * qz + qw * qx) * z,
        2.0 * (qx * qz + qw * qy) * x + 2.0 * (qy * qz - qw * qx) * y + (1.0 - 2.0 * (qx * qx + qy * qy)) * z,
    )


@njit(cache=True, fastmath=True, inline="always")
def rotate_world(qw, qx, qy, qz, cx, cy, cz):  # pragma: no cover - numba
    """dq(c) (x) q, normalised: q rotated by the small NED-frame rotation vector c (rad)."""
    hx = 0.5 * cx
    hy = 0.5 * cy
    hz = 0.5 * cz
    nw = qw - hx * qx - hy * qy - hz * qz
    nx = qx + hx * qw + hy * qz - hz * qy
    ny = qy - hx * qz + hy * qw + hz * qx
    nz = qz + hx * qy - hy * qx + hz * qw
    n = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    return nw * n, nx * n, ny * n, nz * n


@njit(cache=True, fastmath=True)
def quat_yaw(qw, qx, qy, qz):  # pragma: no cover - numba
    """Heading (rad, from north, ZYX yaw) of a body-to-NED quaternion."""
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
