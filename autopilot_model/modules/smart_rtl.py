"""ArduCopter's SMART_RTL (mode 21, ``ModeSmartRTL`` with ``AP_SmartRTL``) for the model.

The path starts (``AP_SmartRTL::set_home``) once the position is good, again at arming and at every
DO_SET_HOME to the current location; while armed (and not in SMART_RTL) a point is added each time
the vehicle is SRTL_ACCURACY metres from the last one, at most SRTL_POINTS points (when full, the mode
becomes unavailable, as ArduCopter when its cleanup cannot make room). Entering SMART_RTL needs the
path to be active (``AP_SmartRTL::is_active``): otherwise the mode change is refused and the caller
(a failsafe) falls back to RTL or LAND. On the ground it is accepted and does nothing. In the air the
mode flies the points back in reverse order at WPNAV_SPEED, the last one (where the path started) 2 m
higher (``PRELAND_POSITION``), then lands there (RTL_ALT_FINAL = 0) and stays in SMART_RTL after the disarm.

Differences kept (``docs/conformance.md``): ArduCopter prunes loops and simplifies the path
(Ramer-Douglas-Peucker) in the background and waits for that cleanup before leaving; the model keeps
every point it recorded, so it flies back over the same track with a few more corners.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autopilot_model.modules.vehicle_api import VehicleApi
    from autopilot_model.params import ParamStore

_PRELAND_UP_M = 2.0
_REACHED_M = 1.0


def define_smart_rtl_params(params: ParamStore) -> None:
    params.define("SRTL_ACCURACY", 2.0, 0.0, 10.0, doc="SmartRTL: distance between recorded points (m)")
    params.define("SRTL_POINTS", 300.0, 0.0, 500.0, "int", doc="SmartRTL: maximum number of points")


class SmartRtl:
    """The recorded path and the return along it."""

    def __init__(self, vehicle: VehicleApi) -> None:
        self.v = vehicle
        define_smart_rtl_params(vehicle.params)
        self.path: list[tuple[float, float, float]] = []
        self.active = False
        self._was_armed = False
        self._returning: list[tuple[float, float, float]] = []
        self.stage = "idle"

    # --- recording --------------------------------------------------------------------------------
    def record(self, recording: bool) -> None:
        """Each navigation step: keep the path while armed (``recording``: not in SMART_RTL)."""
        nav = self.v.nav
        if (nav.armed and not self._was_armed) or (not self.path and self.v.estimator.healthy):
            self.set_home()  # AP_SmartRTL::set_home: the first good position, and at arming
        self._was_armed = nav.armed
        if not (nav.armed and recording and self.active):
            return
        p = self._pos()
        if math.dist(p, self.path[-1]) >= max(0.01, self.v.params.get("SRTL_ACCURACY")):
            if len(self.path) >= int(self.v.params.get("SRTL_POINTS")):
                self.active = False  # buffer full: "SmartRTL deactivated: buffer full"
                return
            self.path.append(p)

    def set_home(self) -> None:
        """Restart the path here (also ``Copter::set_home_to_current_location``: DO_SET_HOME param1 1)."""
        self.path = [self._pos()]
        self.active = self.v.params.get("SRTL_POINTS") > 0

    def _pos(self) -> tuple[float, float, float]:
        n, e, d = self.v.state.position_ned
        return (float(n), float(e), float(d))

    # --- the mode ---------------------------------------------------------------------------------
    def start(self) -> tuple[bool, str]:
        """Entering SMART_RTL: refused without a path (ArduCopter's init returns false)."""
        nav = self.v.nav
        if not (self.active and self.path):
            return False, "SmartRTL Unavailable"
        if not nav.armed or nav.landed_state == 1:  # on the ground: nothing to fly
            self.stage = "idle"
            return True, ""
        self._returning = list(self.path)
        self.stage = "path"
        self._next()
        return True, ""

    def _next(self) -> None:
        nav = self.v.nav
        if not self._returning:
            self.stage = "land"
            nav.land()
            return
        point = self._returning.pop()
        if not self._returning:
            self.stage = "preland"
            point = (point[0], point[1], point[2] - _PRELAND_UP_M)
        nav.goto(point, self.v.params.get("WPNAV_SPEED") / 100.0)
        self._target = point

    def update(self) -> None:
        if self.stage not in ("path", "preland"):
            return
        if not self.v.nav.armed:
            self.stage = "idle"
            return
        g = self.v.guidance
        if g.at_target or (math.dist(self._pos(), self._target) < _REACHED_M and self.stage == "path"):
            self._next()
