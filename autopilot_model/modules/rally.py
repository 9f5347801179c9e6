"""Rally points used by RTL, as ArduCopter's ``AP_Rally::calc_best_rally_or_home_location``.

The rally plan (mission type RALLY, MAV_CMD_NAV_RALLY_POINT items: lat, lon, altitude in the item's
frame) is uploaded with the mission protocol. RTL returns to the rally point nearest the vehicle; with
RALLY_INCL_HOME 1 (ArduCopter's default for copters) only if it is nearer than home. The return altitude
is the largest of the rally point's altitude above home, RTL_ALT and the present altitude, as
``ModeRTL::compute_return_target``; the landing is at the rally point. RALLY_LIMIT_KM (0.3) only makes
ArduCopter warn that the nearest point is far; the model does not warn.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from taskflight_common.geo import geodetic_to_ned

from .mission_items import RALLY, RALLY_POINT, RELATIVE_FRAMES

if TYPE_CHECKING:
    from autopilot_model.modules.mission_store import MissionStore
    from autopilot_model.modules.vehicle_api import VehicleApi
    from autopilot_model.params import ParamStore


def define_rally_params(params: ParamStore) -> None:
    params.define("RALLY_LIMIT_KM", 0.3, 0.0, 100.0, doc="warn when the nearest rally point is further (km)")
    params.define("RALLY_INCL_HOME", 1.0, 0.0, 1.0, "int", doc="RTL: use home if it is nearer than every "
                  "rally point")


def return_target(vehicle: VehicleApi, store: MissionStore | None
                  ) -> tuple[tuple[float, float, float], float] | None:
    """(rally point NED, its altitude above home) when RTL should go there; None: home."""
    if store is None or store.count(RALLY) == 0:
        return None
    origin = vehicle.state.origin
    home = vehicle.home
    n, e, _ = (float(x) for x in vehicle.state.position_ned)
    best: tuple[float, tuple[float, float, float], float] | None = None
    for it in store.get(RALLY):
        if it.command != RALLY_POINT or (it.x == 0 and it.y == 0):
            continue
        alt_above_home = it.z if it.frame in RELATIVE_FRAMES else it.z - home[2]
        p = geodetic_to_ned(origin, it.lat, it.lon, home[2] + alt_above_home)
        dist = math.hypot(p[0] - n, p[1] - e)
        if best is None or dist < best[0]:
            best = (dist, (float(p[0]), float(p[1]), float(p[2])), float(alt_above_home))
    if best is None:
        return None
    if vehicle.params.get("RALLY_INCL_HOME") >= 1:
        hn, he, _ = geodetic_to_ned(origin, home[0], home[1], home[2])
        if math.hypot(hn - n, he - e) <= best[0]:
            return None
    return best[1], best[2]
