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

* **the state vector** (:attr:`StateInterface.vector`): ``[p(3), v(3), q(4), w(3), a(3)]`` (NED position,
  NED velocity, quaternion, body rates, NED acceleration; layout :data:`SV_POS` ... :data:`SV_SIZE`), a
  read-only numpy view of an array the interface owns. It is the format the numba kernels of the 500 Hz
  control chain read (seed 002 Fig. 2: the controllers read the state interface): the controller gets
  this view, no copy and no conversion.

Every ``set_*`` validates its input (right length, finite; a quaternion of non-zero norm, a proper rotation
matrix) and raises :class:`ValueError` leaving the state unchanged. A write stores the value in its own
format and invalidates the other formats of that quantity only; a read of another format converts once and
caches the result until the next write of that quantity. ``conversions`` counts the conversions actually
performed, per target format, so the once-per-update rule can be checked.

Writers. The estimator is the one writer of the 500 Hz path: it writes its checked (finite) estimate
straight into the interface's array (:meth:`StateInterface.estimate_buffer`, from inside its own numba
finite-check kernel, so publishing costs no extra call) and then calls :meth:`StateInterface.publish`,
which stamps ``time_us`` and marks every other format stale. Any other writer (a test, a ground-truth
switch) uses the validated ``set_*`` / :meth:`StateInterface.update`; the vector is then refreshed from
the written formats on its next read, once, converting only what changed (e.g. an Euler write becomes a
quaternion in the vector and counts one ``quat`` conversion). Copying the same representation between
the array and a tuple (NED position, velocity, rates, acceleration, the quaternion) is not a format
conversion and is not counted.

Performance (the estimator writes at 500 Hz and the controller reads at 500 Hz inside a loop that runs
many times faster than real time): a publish is a few attribute stores; the control chain's read is a
flag test and the cached view; the tuple formats (navigation, flight modes, telemetry at 10-50 Hz) are
built from the array only when somebody reads them, once per update; the geodetic conversion
(ArduPilot's flat-earth convention, :mod:`taskflight_common.geo`) only runs when somebody actually reads
the other
position format (``bench/bench_lockstep.py`` and ``bench/bench_hotpath.py`` measure it).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from autopilot_model.state_formats import (  # the attitude conversions, re-exported
    Mat3,
    Quat,
    Vec3,
    euler_to_matrix,
    euler_to_quat,
    matrix_to_euler,
    matrix_to_quat,
    quat_to_euler,
    quat_to_matrix,
)
from taskflight_common.geo import geodetic_to_ned, ned_to_geodetic
from taskflight_common.validate import finite3 as _vec3

__all__ = [
    "SV_ACC",
    "SV_POS",
    "SV_QUAT",
    "SV_RATES",
    "SV_SIZE",
    "SV_VEL",
    "StateInterface",
    "euler_to_matrix",
    "euler_to_quat",
    "matrix_to_euler",
    "matrix_to_quat",
    "quat_to_euler",
    "quat_to_matrix",
]

log = logging.getLogger(__name__)

_ORTHO_TOL = 1e-3  # accepted deviation of R R^T from identity on a matrix write

#: Offsets in the state vector (:attr:`StateInterface.vector`): NED position, NED velocity, quaternion
#: (w, x, y, z), body rates, NED acceleration. The first 13 entries are the estimator's own layout.
SV_POS, SV_VEL, SV_QUAT, SV_RATES, SV_ACC = 0, 3, 6, 10, 13
SV_SIZE = 16


# --------------------------------------------------------------------------------------------------
# Input validation: ValueError (never TypeError) and nothing written on failure.
# --------------------------------------------------------------------------------------------------
class StateInterface:
    """The vehicle-state blackboard of seed 002 Sec. 3.1: write in one format, read in any.

    Write with the ``set_*`` methods (or :meth:`update` for several quantities at once, atomically), or, for
    the estimator, into :meth:`estimate_buffer` followed by :meth:`publish`; read with the properties
    (:attr:`vector` for the numba kernels). Derived formats are computed lazily, once per write (see
    ``conversions``).

    Args:
        origin: ``(lat deg, lon deg, alt m AMSL)`` of the local NED frame.
    """

    __slots__ = (
        "_acc",
        "_buf",
        "_eul",
        "_geo_src",
        "_gs",
        "_lla",
        "_ned",
        "_quat",
        "_rates",
        "_rmat",
        "_va",
        "_vel",
        "_view",
        "_vok",
        "_vp",
        "_vq",
        "_vv",
        "_vw",
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
        # tuple formats: None = not current (derive it from the vector or another format on read)
        self._ned: Vec3 | None = (0.0, 0.0, 0.0)
        self._lla: Vec3 | None = None
        self._geo_src = False  # True when the position was last written as geodetic
        self._quat: Quat | None = (1.0, 0.0, 0.0, 0.0)
        self._eul: Vec3 | None = None
        self._rmat: Mat3 | None = None
        self._vel: Vec3 | None = (0.0, 0.0, 0.0)
        self._gs: float | None = 0.0
        self._acc: Vec3 | None = (0.0, 0.0, 0.0)
        self._rates: Vec3 | None = (0.0, 0.0, 0.0)
        # the state vector (owned array, read-only view) and which of its sections are current
        self._buf = np.zeros(SV_SIZE)
        self._buf[SV_QUAT] = 1.0
        self._view = self._buf.view()
        self._view.flags.writeable = False
        self._vp = self._vv = self._vq = self._vw = self._va = True
        self._vok = True  # all five sections current

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
            self._vp = self._vok = False
        else:
            self._lla = None

    def set_position_ned(self, p: Sequence[float]) -> None:
        """Write the position as local NED metres relative to ``origin``."""
        self._ned = _vec3(p, "position_ned")
        self._lla = None
        self._geo_src = False
        self._vp = self._vok = False

    def set_position_geodetic(self, lla: Sequence[float]) -> None:
        """Write the position as (lat deg, lon deg, alt m AMSL)."""
        lat, lon, alt = _vec3(lla, "position_geodetic")
        if not -90.0 <= lat <= 90.0:
            raise ValueError(f"position_geodetic: latitude {lat} out of [-90, 90]")
        self._lla = (lat, lon, alt)
        self._ned = None
        self._geo_src = True
        self._vp = self._vok = False

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
        self._vq = self._vok = False

    def set_euler(self, e: Sequence[float]) -> None:
        """Write the attitude as Euler angles (roll, pitch, yaw), ZYX, radians."""
        self._eul = _vec3(e, "euler")
        self._quat = None
        self._rmat = None
        self._vq = self._vok = False

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
        self._vq = self._vok = False

    def set_velocity_ned(self, v: Sequence[float]) -> None:
        """Write the NED velocity (m/s)."""
        self._vel = _vec3(v, "velocity_ned")
        self._gs = None
        self._vv = self._vok = False

    def set_acceleration_ned(self, a: Sequence[float]) -> None:
        """Write the NED acceleration (m/s^2)."""
        self._acc = _vec3(a, "acceleration_ned")
        self._va = self._vok = False

    def set_body_rates(self, w: Sequence[float]) -> None:
        """Write the body angular rates (p, q, r) in rad/s."""
        self._rates = _vec3(w, "body_rates")
        self._vw = self._vok = False

    def estimate_buffer(self) -> np.ndarray:
        """The writable state vector (layout :data:`SV_POS` ... :data:`SV_SIZE`), for the one trusted
        writer of the 500 Hz path, the estimator (seed 002 Sec. 3.1: INS -> state interface).

        The writer fills it with a finite estimate and a unit quaternion (the estimator checks its own
        output and never writes a diverged state), then calls :meth:`publish`. Nothing is validated
        here: every other writer uses the ``set_*`` methods.
        """
        return self._buf

    def publish(self, time_us: int) -> None:
        """The estimator's single publication per main-loop iteration, after it wrote
        :meth:`estimate_buffer`: the vector is the state, every other format is stale (rebuilt from the
        vector when read, once), ``time_us`` is stamped."""
        self._ned = None
        self._lla = None
        self._geo_src = False
        self._vel = None
        self._gs = None
        self._quat = None
        self._eul = None
        self._rmat = None
        self._rates = None
        self._acc = None
        self._vp = self._vv = self._vq = self._vw = self._va = self._vok = True
        self.time_us = time_us

    def publish_estimate(self, time_us: int, p: Vec3, v: Vec3, q: Quat, w: Vec3, a: Vec3) -> None:
        """A trusted write of a whole estimate as float tuples (NED position, NED velocity, unit quaternion,
        body rates, NED acceleration), without per-field validation: for writers that hold tuples (the
        estimator itself writes :meth:`estimate_buffer` instead). The vector is refreshed on its next
        read."""
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
        self._vp = self._vv = self._vq = self._vw = self._va = self._vok = False
        self.time_us = time_us

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
            self._vp = self._vok = False
        if quat is not None or euler is not None or rot_matrix is not None:
            self._quat, self._eul, self._rmat = staged._quat, staged._eul, staged._rmat
            self._vq = self._vok = False
        if velocity_ned is not None:
            self._vel = staged._vel
            self._gs = None
            self._vv = self._vok = False
        if acceleration_ned is not None:
            self._acc = staged._acc
            self._va = self._vok = False
        if body_rates is not None:
            self._rates = staged._rates
            self._vw = self._vok = False
        self.time_us = t

    # ------------------------------------------------------------------------------------ reads
    @property
    def vector(self) -> np.ndarray:
        """The state vector ``[p(3), v(3), q(4), w(3), a(3)]`` (:data:`SV_POS` ... :data:`SV_SIZE`): a
        read-only view of the interface's own array, what the control chain's kernels read. After a
        ``set_*`` write the changed sections are rebuilt once, on this read."""
        if not self._vok:
            self._refresh_vector()
        return self._view

    def _refresh_vector(self) -> None:
        b = self._buf
        if not self._vp:
            b[SV_POS:SV_POS + 3] = self.position_ned
            self._vp = True
        if not self._vv:
            b[SV_VEL:SV_VEL + 3] = self.velocity_ned
            self._vv = True
        if not self._vq:
            b[SV_QUAT:SV_QUAT + 4] = self.quat
            self._vq = True
        if not self._vw:
            b[SV_RATES:SV_RATES + 3] = self.body_rates
            self._vw = True
        if not self._va:
            b[SV_ACC:SV_ACC + 3] = self.acceleration_ned
            self._va = True
        self._vok = True

    def _from_vector(self, start: int, n: int) -> tuple[float, ...]:
        return tuple(self._buf[start:start + n].tolist())

    @property
    def position_ned(self) -> Vec3:
        """Local NED position (m) relative to ``origin``."""
        p = self._ned
        if p is None:
            if self._vp:
                p = self._ned = self._from_vector(SV_POS, 3)  # type: ignore[assignment]
            else:
                lat, lon, alt = self._lla  # type: ignore[misc]
                n, e, d = geodetic_to_ned(self.origin, lat, lon, alt)
                p = self._ned = (float(n), float(e), float(d))
                self.conversions["ned"] += 1
        return p  # type: ignore[return-value]

    @property
    def position_geodetic(self) -> Vec3:
        """Geodetic position (lat deg, lon deg, alt m AMSL)."""
        g = self._lla
        if g is None:
            n, e, d = self.position_ned
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

    def _quat_or_none(self) -> Quat | None:
        """The quaternion if it is current as a tuple or in the vector (no conversion), else None."""
        q = self._quat
        if q is None and self._vq:
            q = self._quat = self._from_vector(SV_QUAT, 4)  # type: ignore[assignment]
        return q

    @property
    def quat(self) -> Quat:
        """Attitude quaternion (w, x, y, z), body to NED."""
        q = self._quat_or_none()
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
            q = self._quat_or_none()
            e = quat_to_euler(q) if q is not None else matrix_to_euler(self._rmat)  # type: ignore[arg-type]
            self._eul = e
            self.conversions["euler"] += 1
        return e

    @property
    def rot_matrix(self) -> Mat3:
        """Rotation matrix body -> NED as a tuple of three row tuples."""
        m = self._rmat
        if m is None:
            q = self._quat_or_none()
            m = quat_to_matrix(q) if q is not None else euler_to_matrix(self._eul)  # type: ignore[arg-type]
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
        v = self._vel
        if v is None:
            v = self._vel = self._from_vector(SV_VEL, 3)  # type: ignore[assignment]
        return v  # type: ignore[return-value]

    @property
    def ground_speed(self) -> float:
        """Horizontal speed (m/s)."""
        g = self._gs
        if g is None:
            v = self.velocity_ned
            g = self._gs = math.hypot(v[0], v[1])
            self.conversions["ground_speed"] += 1
        return g

    @property
    def acceleration_ned(self) -> Vec3:
        """NED acceleration (m/s^2)."""
        a = self._acc
        if a is None:
            a = self._acc = self._from_vector(SV_ACC, 3)  # type: ignore[assignment]
        return a  # type: ignore[return-value]

    @property
    def body_rates(self) -> Vec3:
        """Body angular rates (p, q, r), rad/s."""
        w = self._rates
        if w is None:
            w = self._rates = self._from_vector(SV_RATES, 3)  # type: ignore[assignment]
        return w  # type: ignore[return-value]

    def __repr__(self) -> str:
        return (
            f"StateInterface(t={self.time_us}us, ned={self.position_ned}, euler={self.euler}, "
            f"v={self.velocity_ned})"
        )
