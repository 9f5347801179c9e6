"""ArduCopter's ``AutoYaw`` (ArduCopter/autoyaw.cpp) for the model's autonomous modes.

MAV_CMD_CONDITION_YAW (a command, or a mission item) sets a *fixed* heading: param1 the angle (deg,
0..360), param2 the rate (deg/s, 0 = the default, the model's maximum yaw rate), param3 the direction
(-1 counter-clockwise, +1 clockwise; for a relative turn the sign of the offset), param4 1 = relative
to the present heading. MAV_CMD_DO_SET_ROI_LOCATION / DO_SET_ROI (command or mission item) points the
nose at a location until cleared (a location of 0, 0, 0, or DO_SET_ROI_NONE) or the mode changes.

As in ArduCopter the heading is flown only by the modes that use auto yaw (GUIDED, AUTO, RTL,
SMART_RTL); in the others the command is accepted and has no effect. Every mode change clears it
(``AutoYaw::set_mode_to_default``). Differences kept: the model turns the shortest way even when param3
asks for the long way round (its setpoint generator has one yaw law); see ``docs/conformance.md``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from taskflight_common.geo import geodetic_to_ned

if TYPE_CHECKING:
    from autopilot_model.modules.vehicle_api import VehicleApi

#: ArduCopter's ``reached_fixed_yaw_target``: within 2 degrees
REACHED_RAD = math.radians(2.0)

NONE = "none"
FIXED = "fixed"
ROI = "roi"


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class AutoYaw:
    """The heading the autonomous modes fly: none (their own), fixed (CONDITION_YAW) or ROI."""

    def __init__(self, vehicle: VehicleApi) -> None:
        self.v = vehicle
        self.mode = NONE
        self.yaw = 0.0  # fixed target (rad)
        self.rate = 0.0  # rad/s, 0 = default
        self.roi_ned: tuple[float, float, float] | None = None

    def reset(self) -> None:
        """A mode change: back to the mode's own heading."""
        self.mode = NONE
        self.roi_ned = None

    def set_fixed(self, angle_deg: float, rate_dps: float, direction: float, relative: bool,
                  fly: bool = True) -> None:
        """CONDITION_YAW (already checked: 0 <= angle <= 360); ``fly``: turn now (an auto-yaw mode)."""
        if relative:
            base = self.yaw if self.mode == FIXED else float(self.v.guidance.yaw)
            target = base + math.radians(angle_deg) * (1.0 if direction >= 0 else -1.0)
        else:
            target = math.radians(angle_deg)
        self.yaw = _wrap(target)
        self.rate = math.radians(rate_dps) if rate_dps > 0 else 0.0
        self.mode = FIXED
        if fly:
            self.v.nav.yaw(self.yaw, self.rate or None)

    def set_roi(self, lat: float, lon: float, alt_amsl: float) -> None:
        """DO_SET_ROI(_LOCATION); lat = lon = 0 clears the ROI."""
        if lat == 0.0 and lon == 0.0:
            self.reset()
            return
        self.roi_ned = geodetic_to_ned(self.v.state.origin, lat, lon, alt_amsl)
        self.mode = ROI
        self.update()

    def reached(self) -> bool:
        """``reached_fixed_yaw_target``: the fixed heading is flown to within 2 degrees."""
        if self.mode != FIXED:
            return True
        return abs(_wrap(self.yaw - float(self.v.state.heading))) <= REACHED_RAD

    def update(self) -> None:
        """Point at the ROI (each navigation step); a fixed heading was given once."""
        if self.mode != ROI or self.roi_ned is None:
            return
        n, e, _ = self.v.state.position_ned
        dn, de = self.roi_ned[0] - n, self.roi_ned[1] - e
        if math.hypot(dn, de) > 1.0:  # ArduCopter stops turning within a metre of the ROI
            self.v.nav.yaw(math.atan2(de, dn), None)
