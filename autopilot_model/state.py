"""The state interface: one blackboard for the vehicle state (seed 002 Sec. 3.1, Fig. 2).

Seed 002 Sec. 3.1: the state estimation filters push their result to a blackboard, the *state interface*,
where "new data can be pushed in any supported format (e.g. Euler angles, rotation matrix or quaternion in
the case of attitude representation), while they can be retrieved from any other components [...] in any
format as well. If a format transformation is required [...], the conversion is performed on the fly, only
once, until a new update is available for the state."

:class:`StateInterface` implements exactly that:

* **position**: local NED (m) relative to ``origin`` or geodetic (lat deg, lon deg, alt m AMSL);
* **attitude**: quaternion ``(w, x, y, z)`` rotating body to NED, Euler ``(roll, pitch, yaw)`` (ZYX,
  rad) or a rotation matrix (body to NED, 3x3, tuple of row tuples on read; tuple-of-tuples, list or
  numpy on write);
* **velocity** NED, **acceleration** NED, **body rates** (p, q, r rad/s) and ``time_us`` of the update.

Every ``set_*`` validates its input (right length, finite; a quaternion of non-zero norm, a proper rotation
matrix) and raises :class:`ValueError` leaving the state unchanged. A write stores the value in its own
format and invalidates the other formats of that quantity only; a read of another format converts once and
caches the result until the next write of that quantity. ``conversions`` counts the conversions actually
performed, per target format, so the once-per-update rule can be checked.

Performance (the estimator writes at 500 Hz and every controller reads at 500 Hz inside a loop that runs many
times faster than real time): plain attributes, tuples of floats and :mod:`math`; the geodetic conversion
(ArduPilot's flat-earth convention, :mod:`taskflight.geo`) only runs when somebody actually reads the other
position format.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

from taskflight.geo import geodetic_to_ned, ned_to_geodetic
from taskflight.validate import finite3 as _vec3

__all__ = [
    "StateInterface",
    "euler_to_matrix",
    "euler_to_quat",
    "matrix_to_euler",
    "matrix_to_quat",
    "quat_to_euler",
    "quat_to_matrix",
]

log = logging.getLogger(__name__)

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]

_ORTHO_TOL = 1e-3  # accepted deviation of R R^T from identity on a matrix write


# --------------------------------------------------------------------------------------------------
# Attitude conversions (pure math; body -> NED, ZYX Euler). Public: controllers use them too.
# --------------------------------------------------------------------------------------------------
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


# --------------------------------------------------------------------------------------------------
# Input validation: ValueError (never TypeError) and nothing written on failure.
# --------------------------------------------------------------------------------------------------
class StateInterface:
    """The vehicle-state blackboard of seed 002 Sec. 3.1: write in one format, read in any.

    Write with the ``set_*`` methods (or :meth:`update` for several quantities at once, atomically); read
    with the properties. Derived formats are computed lazily, once per write (see ``conversions``).

    Args:
        origin: ``(lat deg, lon deg, alt m AMSL)`` of the local NED frame.
    """

    __slots__ = (
        "_acc",
        "_eul",
        "_geo_src",
        "_gs",
        "_lla",
        "_ned",
        "_quat",
        "_rates",
        "_rmat",
        "_vel",
        "conversions",
        "origin",
        "time_us",
    )

    def __init__(self, origin: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        self.origin: Vec3 = self._check_origin(origin)
        self.time_us: int = 0
        #: conversions performed so far, per *target* format ("euler", "quat", "matrix", "ned",
        #: "geodetic", "ground_speed").
        self.conversions: dict[str, int] = {
            "euler": 0,
            "quat": 0,
            "matrix": 0,
            "ned": 0,
            "geodetic": 0,
            "ground_speed": 0,
        }
        self._ned: Vec3 | None = (0.0, 0.0, 0.0)
        self._lla: Vec3 | None = None
        self._geo_src = False  # True when the position was last written as geodetic
        self._quat: Quat | None = (1.0, 0.0, 0.0, 0.0)
        self._eul: Vec3 | None = None
        self._rmat: Mat3 | None = None
        self._vel: Vec3 = (0.0, 0.0, 0.0)
        self._gs: float | None = 0.0
        self._acc: Vec3 = (0.0, 0.0, 0.0)
        self._rates: Vec3 = (0.0, 0.0, 0.0)

    # ---------------------------------------------------------------------------------- helpers
    @staticmethod
    def _check_origin(origin: Sequence[float]) -> Vec3:
        lat, lon, alt = _vec3(origin, "origin")
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 360.0):
            raise ValueError(f"origin: latitude/longitude out of range: {origin!r}")
        return (lat, lon, alt)

    @property
    def conversions_total(self) -> int:
        """Total number of format conversions performed since construction."""
        return sum(self.conversions.values())

    # ----------------------------------------------------------------------------------- writes
    def set_origin(self, origin: Sequence[float]) -> None:
        """Move the NED origin ``(lat, lon, alt AMSL)``; the written position format is kept."""
        self.origin = self._check_origin(origin)
        if self._geo_src:
            self._ned = None
        else:
            self._lla = None

    def set_position_ned(self, p: Sequence[float]) -> None:
        """Write the position as local NED metres relative to ``origin``."""
        self._ned = _vec3(p, "position_ned")
        self._lla = None
        self._geo_src = False

    def set_position_geodetic(self, lla: Sequence[float]) -> None:
        """Write the position as (lat deg, lon deg, alt m AMSL)."""
        lat, lon, alt = _vec3(lla, "position_geodetic")
        if not -90.0 <= lat <= 90.0:
            raise ValueError(f"position_geodetic: latitude {lat} out of [-90, 90]")
        self._lla = (lat, lon, alt)
        self._ned = None
        self._geo_src = True

    def set_quat(self, q: Sequence[float]) -> None:
        """Write the attitude as a quaternion (w, x, y, z), body to NED; normalised on write."""
        try:
            w, x, y, z = q
            w = float(w)
            x = float(x)
            y = float(y)
            z = float(z)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"quat: expected 4 numbers, got {q!r}") from exc
        n2 = w * w + x * x + y * y + z * z
        if not (1e-12 < n2 < math.inf):  # also rejects NaN
            raise ValueError(f"quat: norm must be finite and non-zero, got {q!r}")
        if n2 != 1.0:
            n = 1.0 / math.sqrt(n2)
            w *= n
            x *= n
            y *= n
            z *= n
        self._quat = (w, x, y, z)
        self._eul = None
        self._rmat = None

    def set_euler(self, e: Sequence[float]) -> None:
        """Write the attitude as Euler angles (roll, pitch, yaw), ZYX, radians."""
        self._eul = _vec3(e, "euler")
        self._quat = None
        self._rmat = None

    def set_rot_matrix(self, m: Any) -> None:
        """Write the attitude as a 3x3 rotation matrix body -> NED (rows; tuples, lists or numpy)."""
        try:
            rows = tuple(m)
            if len(rows) != 3:
                raise ValueError("need 3 rows")
            r0, r1, r2 = (_vec3(r, "rot_matrix row") for r in rows)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"rot_matrix: expected a finite 3x3 matrix, got {m!r}") from exc
        mat = (r0, r1, r2)
        for i in range(3):
            for j in range(i, 3):
                dot = mat[i][0] * mat[j][0] + mat[i][1] * mat[j][1] + mat[i][2] * mat[j][2]
                if abs(dot - (1.0 if i == j else 0.0)) > _ORTHO_TOL:
                    raise ValueError(f"rot_matrix: not orthonormal (row {i}.row {j} = {dot:.6f})")
        det = (
            r0[0] * (r1[1] * r2[2] - r1[2] * r2[1])
            - r0[1] * (r1[0] * r2[2] - r1[2] * r2[0])
            + r0[2] * (r1[0] * r2[1] - r1[1] * r2[0])
        )
        if det < 0.0:
            raise ValueError("rot_matrix: determinant -1 (a reflection, not a rotation)")
        self._rmat = mat
        self._quat = None
        self._eul = None

    def set_velocity_ned(self, v: Sequence[float]) -> None:
        """Write the NED velocity (m/s)."""
        self._vel = _vec3(v, "velocity_ned")
        self._gs = None

    def set_acceleration_ned(self, a: Sequence[float]) -> None:
        """Write the NED acceleration (m/s^2)."""
        self._acc = _vec3(a, "acceleration_ned")

    def publish_estimate(self, time_us: int, p: Vec3, v: Vec3, q: Quat, w: Vec3, a: Vec3) -> None:
        """The estimator's single write per main-loop iteration (seed 002 Sec. 3.1: INS -> state).

        NED position, NED velocity, unit quaternion, body rates and NED acceleration as float tuples.
        This is the trusted fast path of the one writer of the estimate: the estimator guarantees the
        values are finite and the quaternion normalised (it checks its own output and never publishes a
        diverged state), so no per-field validation runs here; derived formats are invalidated exactly as
        by the ``set_*`` methods.
        """
        self._ned = p
        self._lla = None
        self._geo_src = False
        self._vel = v
        self._gs = None
        self._quat = q
        self._eul = None
        self._rmat = None
        self._rates = w
        self._acc = a
        self.time_us = time_us

    def set_body_rates(self, w: Sequence[float]) -> None:
        """Write the body angular rates (p, q, r) in rad/s."""
        self._rates = _vec3(w, "body_rates")

    def update(
        self,
        time_us: int,
        *,
        position_ned: Sequence[float] | None = None,
        position_geodetic: Sequence[float] | None = None,
        quat: Sequence[float] | None = None,
        euler: Sequence[float] | None = None,
        rot_matrix: Any = None,
        velocity_ned: Sequence[float] | None = None,
        acceleration_ned: Sequence[float] | None = None,
        body_rates: Sequence[float] | None = None,
    ) -> None:
        """Write several quantities and ``time_us`` at once, all or nothing.

        Everything is validated first; on a :class:`ValueError` nothing at all is written.
        """
        if position_ned is not None and position_geodetic is not None:
            raise ValueError("update: give position_ned or position_geodetic, not both")
        if sum(x is not None for x in (quat, euler, rot_matrix)) > 1:
            raise ValueError("update: give one attitude format only")
        staged = StateInterface.__new__(StateInterface)
        staged._ned = staged._lla = staged._quat = staged._eul = staged._rmat = None
        if position_ned is not None:
            staged.set_position_ned(position_ned)
        if position_geodetic is not None:
            staged.set_position_geodetic(position_geodetic)
        if quat is not None:
            staged.set_quat(quat)
        if euler is not None:
            staged.set_euler(euler)
        if rot_matrix is not None:
            staged.set_rot_matrix(rot_matrix)
        if velocity_ned is not None:
            staged.set_velocity_ned(velocity_ned)
        if acceleration_ned is not None:
            staged.set_acceleration_ned(acceleration_ned)
        if body_rates is not None:
            staged.set_body_rates(body_rates)
        try:
            t = int(time_us)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"time_us: expected an integer, got {time_us!r}") from exc
        # commit
        if position_ned is not None or position_geodetic is not None:
            self._ned, self._lla, self._geo_src = staged._ned, staged._lla, staged._geo_src
        if quat is not None or euler is not None or rot_matrix is not None:
            self._quat, self._eul, self._rmat = staged._quat, staged._eul, staged._rmat
        if velocity_ned is not None:
            self._vel = staged._vel
            self._gs = None
        if acceleration_ned is not None:
            self._acc = staged._acc
        if body_rates is not None:
            self._rates = staged._rates
        self.time_us = t

    # ------------------------------------------------------------------------------------ reads
    @property
    def position_ned(self) -> Vec3:
        """Local NED position (m) relative to ``origin``."""
        p = self._ned
        if p is None:
            lat, lon, alt = self._lla  # type: ignore[misc]
            n, e, d = geodetic_to_ned(self.origin, lat, lon, alt)
            p = self._ned = (float(n), float(e), float(d))
            self.conversions["ned"] += 1
        return p

    @property
    def position_geodetic(self) -> Vec3:
        """Geodetic position (lat deg, lon deg, alt m AMSL)."""
        g = self._lla
        if g is None:
            n, e, d = self._ned  # type: ignore[misc]
            lat, lon, alt = ned_to_geodetic(self.origin, n, e, d)
            g = self._lla = (float(lat), float(lon), float(alt))
            self.conversions["geodetic"] += 1
        return g

    @property
    def alt_rel(self) -> float:
        """Height above the origin (m, up), i.e. minus the NED down coordinate."""
        p = self._ned
        if p is None:
            p = self.position_ned
        return -p[2]

    @property
    def quat(self) -> Quat:
        """Attitude quaternion (w, x, y, z), body to NED."""
        q = self._quat
        if q is None:
            q = euler_to_quat(self._eul) if self._eul is not None else matrix_to_quat(self._rmat)  # type: ignore[arg-type]
            self._quat = q
            self.conversions["quat"] += 1
        return q

    @property
    def euler(self) -> Vec3:
        """Euler angles (roll, pitch, yaw), ZYX, radians; yaw in [-pi, pi]."""
        e = self._eul
        if e is None:
            e = quat_to_euler(self._quat) if self._quat is not None else matrix_to_euler(self._rmat)  # type: ignore[arg-type]
            self._eul = e
            self.conversions["euler"] += 1
        return e

    @property
    def rot_matrix(self) -> Mat3:
        """Rotation matrix body -> NED as a tuple of three row tuples."""
        m = self._rmat
        if m is None:
            m = quat_to_matrix(self._quat) if self._quat is not None else euler_to_matrix(self._eul)  # type: ignore[arg-type]
            self._rmat = m
            self.conversions["matrix"] += 1
        return m

    @property
    def heading(self) -> float:
        """Yaw angle (rad, [-pi, pi], 0 = north, positive clockwise seen from above)."""
        e = self._eul
        if e is None:
            e = self.euler
        return e[2]

    @property
    def velocity_ned(self) -> Vec3:
        """NED velocity (m/s)."""
        return self._vel

    @property
    def ground_speed(self) -> float:
        """Horizontal speed (m/s)."""
        g = self._gs
        if g is None:
            v = self._vel
            g = self._gs = math.hypot(v[0], v[1])
            self.conversions["ground_speed"] += 1
        return g

    @property
    def acceleration_ned(self) -> Vec3:
        """NED acceleration (m/s^2)."""
        return self._acc

    @property
    def body_rates(self) -> Vec3:
        """Body angular rates (p, q, r), rad/s."""
        return self._rates

    def __repr__(self) -> str:
        return (
            f"StateInterface(t={self.time_us}us, ned={self.position_ned}, euler={self.euler}, "
            f"v={self._vel})"
        )
