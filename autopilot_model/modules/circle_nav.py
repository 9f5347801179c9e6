"""ArduCopter's ``AC_Circle`` for the model: CIRCLE mode (7) and the mission's NAV_LOITER_TURNS.

CIRCLE (``ModeCircle::init``, ``AC_Circle::init``): the centre is CIRCLE_RADIUS ahead of the vehicle
along its heading, the vehicle starts on the circle where it is and flies round it at CIRCLE_RATE
(deg/s; positive clockwise), its nose towards the centre. LOITER_TURNS (``ModeAuto::do_circle``): the
centre is the item's location, the vehicle first flies to the edge, then turns; the item completes
after param1 turns (param3: radius, negative counter-clockwise).

The model flies the circle as a velocity target for its setpoint generator: the tangential speed
``radius * rate`` plus a proportional pull onto the moving point on the circle (radially and in
altitude), so the envelope keeps bounding P_d. The angular rate ramps up at WPNAV_ACCEL like
``AC_Circle``'s ``_angular_vel``. Differences (listed in ``docs/conformance.md``): no pilot stick
input in CIRCLE (ArduCopter: the pitch stick changes the radius, roll the rate).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autopilot_model.modules.vehicle_api import VehicleApi
    from autopilot_model.params import ParamStore

_PULL = 1.0  # 1/s: velocity per metre of error onto the point on the circle


def define_circle_params(params: ParamStore) -> None:
    params.define("CIRCLE_RADIUS", 1000.0, 0.0, 200000.0, doc="CIRCLE mode radius (cm)")
    params.define("CIRCLE_RATE", 20.0, -90.0, 90.0, doc="CIRCLE mode turn rate (deg/s, negative: "
                  "counter-clockwise)")


class CircleNav:
    """One circle being flown: centre (NED), radius (m), rate (rad/s, + clockwise), total angle."""

    def __init__(self, vehicle: VehicleApi) -> None:
        self.v = vehicle
        self.centre: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.radius = 0.0
        self.rate = 0.0
        self.angle = 0.0
        self.angle_total = 0.0
        self._w = 0.0  # present angular rate (ramped)

    def start_here(self, radius: float, rate: float) -> None:
        """CIRCLE mode entry: centre ``radius`` ahead along the heading, start where the vehicle is."""
        n, e, d = (float(x) for x in self.v.state.position_ned)
        yaw = float(self.v.state.heading)
        self.radius = max(0.0, radius)
        self.centre = (n + self.radius * math.cos(yaw), e + self.radius * math.sin(yaw), d)
        self.angle = yaw + math.pi  # the vehicle's bearing from the centre
        self._begin(rate)

    def start_at(self, centre: tuple[float, float, float], radius: float, rate: float) -> None:
        """LOITER_TURNS once at the edge: turn from the vehicle's bearing from ``centre``."""
        n, e, _ = self.v.state.position_ned
        self.centre = centre
        self.radius = max(0.0, radius)
        self.angle = math.atan2(float(e) - centre[1], float(n) - centre[0])
        self._begin(rate)

    def edge_point(self, centre: tuple[float, float, float], radius: float) -> tuple[float, float, float]:
        """The point on the circle nearest the vehicle (``AC_Circle::get_closest_point_on_circle``)."""
        n, e, _ = self.v.state.position_ned
        dn, de = float(n) - centre[0], float(e) - centre[1]
        dist = math.hypot(dn, de)
        if dist < 1e-3:
            yaw = float(self.v.state.heading)  # at the centre: the point behind, as AC_Circle
            dn, de, dist = -math.cos(yaw), -math.sin(yaw), 1.0
        return (centre[0] + dn / dist * radius, centre[1] + de / dist * radius, centre[2])

    def _begin(self, rate: float) -> None:
        self.rate = rate
        self.angle_total = 0.0
        self._w = 0.0

    def update(self, dt: float) -> None:
        """Advance the point on the circle by one step and steer towards it."""
        accel = self.v.params.get("WPNAV_ACCEL") / 100.0 if "WPNAV_ACCEL" in self.v.params else 2.5
        r = self.radius
        w_max = self.rate
        if r > 0.0:  # centripetal acceleration within WPNAV_ACCEL (AC_Circle::calc_velocities)
            w_lim = math.sqrt(accel / r)
            w_max = max(-w_lim, min(w_lim, w_max))
            step = accel / r * dt
        else:
            step = abs(w_max)
        self._w += max(-step, min(step, w_max - self._w))
        self.angle += self._w * dt
        self.angle_total += self._w * dt
        cn, ce, cd = self.centre
        pn, pe = cn + r * math.cos(self.angle), ce + r * math.sin(self.angle)
        tn, te = -math.sin(self.angle) * r * self._w, math.cos(self.angle) * r * self._w
        n, e, d = (float(x) for x in self.v.state.position_ned)
        self.v.nav.velocity((tn + _PULL * (pn - n), te + _PULL * (pe - e), _PULL * (cd - d)))
        if r > 0.5:
            self.v.nav.yaw(math.atan2(ce - e, cn - n), None)  # nose to the centre

    @property
    def turns(self) -> float:
        return abs(self.angle_total) / (2.0 * math.pi)
