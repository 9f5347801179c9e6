"""The online trajectory pieces of the setpoint generator (seed 000 Sec. IV-D, Fig. 9): a ruckig problem
kept while it stays valid (:class:`Planner`), the along/across frame of a straight path
(:class:`PathFrame`) and small vector helpers. :mod:`companion.flight.reference` composes them into the
reference generator of each channel."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from ruckig import ControlInterface, InputParameter, Result, Ruckig, Synchronization, Trajectory

log = logging.getLogger(__name__)

_EPS = 1e-9
Array = np.ndarray


class Planner:
    """One ruckig problem of ``dofs`` degrees of freedom, kept while it stays valid (online use).

    Like ruckig's own ``update()``, a trajectory is only recalculated when the request changes or
    the reference left it (a channel switch, the guard): replanning every tick from a state on a
    time-optimal braking curve would let rounding push it just past the curve and overshoot.
    """

    def __init__(self, dofs: int) -> None:
        self.dofs = dofs
        self._otg = Ruckig(dofs)
        self._inp = InputParameter(dofs)
        self._traj = Trajectory(dofs)
        self.duration = 0.0
        self.t = 0.0
        self.ok = False
        self.stretched = False
        self.plan_key: Array | None = None
        self._target_p: Array | None = None
        self._target_v = np.zeros(dofs)

    @property
    def remaining(self) -> float:
        return max(0.0, self.duration - self.t) if self.ok else 0.0

    def reusable(self, key: Array, p: Array, v: Array, a: Array, goal: float = 0.0,
                 key_tol: float = 1e-9) -> bool:
        """Whether the current trajectory serves ``key`` from state (p, v, a) with a modifier ``goal``."""
        if not self.ok or self.plan_key is None or key.shape != self.plan_key.shape:
            return False
        if not close_to(key, self.plan_key, key_tol):
            return False
        if not self.on_track(p, v, a):
            return False
        rem = self.remaining
        if goal > rem + 1e-6:  # a modifier now needs us to be slower
            return False
        return not (self.stretched and goal < rem - 1e-6)  # or allows us to be faster again

    def on_track(self, p: Array, v: Array, a: Array) -> bool:
        pp, vv, aa = self.state(self.t)
        return close_to(pp, p, 1e-9) and close_to(vv, v, 1e-9) and close_to(aa, a, 1e-9)

    def plan(self, p: Array, v: Array, a: Array, target_p: Array | None, target_v: Array, vmax: Array,
             amax: Array, jmax: Array, goal: float = 0.0, key: Array | None = None) -> bool:
        """Plan to (target_p, target_v), or with ``target_p`` None to velocity ``target_v``; at least
        ``goal`` seconds long (speed modifier) unless the motion is trivial."""
        if not self._calculate(p, v, a, target_p, target_v, vmax, amax, jmax, None):
            return False
        self.stretched = False
        trivial = (target_p is None or close_to(target_p, p, 1e-6)) and close_to(v, target_v, 1e-6) \
            and close_to(a, np.zeros(self.dofs), 1e-6)
        if goal > self.duration + 1e-9 and not trivial:
            if not self._calculate(p, v, a, target_p, target_v, vmax, amax, jmax, goal):
                return False
            self.stretched = True
        self.t = 0.0
        self.plan_key = key
        return True

    def _calculate(self, p: Array, v: Array, a: Array, target_p: Array | None, target_v: Array, vmax: Array,
                   amax: Array, jmax: Array, min_duration: float | None) -> bool:
        inp = self._inp
        inp.control_interface = ControlInterface.Velocity if target_p is None else ControlInterface.Position
        inp.synchronization = Synchronization.Time
        inp.current_position = [float(x) for x in p]
        inp.current_velocity = [float(x) for x in v]
        inp.current_acceleration = [float(x) for x in a]
        inp.target_position = [float(x) for x in (target_p if target_p is not None else p)]
        inp.target_velocity = [float(x) for x in target_v]
        inp.target_acceleration = [0.0] * self.dofs
        inp.max_velocity = [max(float(x), 1e-6) for x in vmax]
        inp.max_acceleration = [max(float(x), 1e-6) for x in amax]
        inp.max_jerk = [max(float(x), 1e-6) for x in jmax]
        inp.minimum_duration = min_duration
        self._target_p = None if target_p is None else np.array(target_p, dtype=float)
        self._target_v = np.array(target_v, dtype=float)
        try:
            result = self._otg.calculate(inp, self._traj)
        except Exception as exc:  # ruckig raises on invalid input or unmapped error codes
            log.debug("ruckig failed (%s) for p=%s v=%s a=%s tp=%s tv=%s", exc, p, v, a, target_p, target_v)
            result = Result.Error
        self.ok = result in (Result.Working, Result.Finished)
        self.duration = float(self._traj.duration) if self.ok else 0.0
        if not self.ok:
            self.plan_key = None
        return self.ok

    def state(self, t: float) -> tuple[Array, Array, Array]:
        """State at ``t`` after the start; after the end it continues with its final velocity."""
        if t < self.duration:
            p, v, a = self._traj.at_time(t)
            return np.array(p), np.array(v), np.array(a)
        # at and after the end: exactly the target, then on with the target velocity
        if self._target_p is not None:
            p_end = self._target_p
        else:
            p_end = np.array(self._traj.at_time(self.duration)[0])
        return p_end + self._target_v * (t - self.duration), self._target_v.copy(), np.zeros(self.dofs)

    def advance(self, dt: float) -> tuple[Array, Array, Array]:
        """Move ``dt`` along the trajectory and return the state there."""
        self.t += dt
        return self.state(self.t)

    def invalidate(self) -> None:
        self.plan_key = None


_NONE = 1.2345e300  # stands for None in a key


def close_to(x: Array, y: Array, tol: float) -> bool:
    """Max-norm closeness, fast for the tiny arrays used here."""
    xs = x.tolist() if isinstance(x, np.ndarray) else list(x)
    ys = y.tolist() if isinstance(y, np.ndarray) else list(y)
    return len(xs) == len(ys) and all(abs(a - b) <= tol for a, b in zip(xs, ys, strict=True))


def plan_key(*parts: float | Array | list[float] | tuple[float, ...] | None) -> Array:
    out: list[float] = []
    for part in parts:
        if part is None:
            out.append(_NONE)
        elif isinstance(part, np.ndarray | list | tuple):
            out.extend(float(x) for x in part)
        else:
            out.append(float(part))
    return np.array(out)


def unit(x: np.ndarray) -> tuple[np.ndarray, float]:
    n = float(np.linalg.norm(x))
    return (x / n if n > _EPS else np.zeros_like(x)), n


def clamp_norm(x: np.ndarray, limit: float) -> tuple[np.ndarray, bool]:
    n = float(np.linalg.norm(x))
    if n > limit:
        return x * (limit / n), True
    return x, False


def perp_basis(u: np.ndarray) -> list[np.ndarray]:
    """Orthonormal vectors spanning the space perpendicular to unit vector ``u`` (2-D or 3-D)."""
    if u.shape[0] == 2:
        return [np.array([-u[1], u[0]])]
    helper = np.array([0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    n1, _ = unit(np.cross(u, helper))
    n2 = np.cross(u, n1)
    return [n1, n2]


def stopping_speed(distance: float, accel: float, jerk: float) -> float:
    """Largest speed from which a jerk-limited stop (using half of ``accel``) fits in ``distance``."""
    a = 0.5 * accel
    d = max(0.0, distance - 0.1)
    k = a * a / jerk
    return -k + math.sqrt(k * k + 2.0 * a * d)


@dataclass
class PathFrame:
    """The line frame of a path plan: along ``u`` from the target, across along ``basis``."""

    dims: int
    u: Array
    basis: list[Array]
    target: Array
    key: Array
    cross_active: bool = False
    t_cross: float = 0.0

    def along_state(self, p: Array, v: Array, a: Array) -> tuple[Array, Array, Array]:
        return (np.array([float((p - self.target) @ self.u)]), np.array([float(v @ self.u)]),
                np.array([float(a @ self.u)]))

    def cross_state(self, p: Array, v: Array, a: Array) -> tuple[Array, Array, Array]:
        return (np.array([float((p - self.target) @ n) for n in self.basis]),
                np.array([float(v @ n) for n in self.basis]), np.array([float(a @ n) for n in self.basis]))
