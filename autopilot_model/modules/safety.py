"""Failsafes of the autopilot model (core task group, 10 Hz), as ArduCopter has them.

* Ground-station heartbeat loss (FS_GCS_ENABLE, FS_GCS_TIMEOUT): only once a GCS heartbeat has been
  seen and only while armed; cleared when heartbeats return.
* Battery (BATT_LOW_VOLT / BATT_CRT_VOLT held for BATT_LOW_TIMER, or BATT_LOW_MAH / BATT_CRT_MAH
  remaining of BATT_CAPACITY; actions BATT_FS_LOW_ACT / BATT_FS_CRT_ACT). The levels latch: low acts
  once, critical once more, until the battery is replaced (a restart).
* Geofence (:mod:`.fence`, ArduPilot's AC_Fence): checked at 10 Hz, armed or not (a breach while
  disarmed fails the pre-arm check); a new breach while armed is announced as ArduCopter does ("Circle
  fence breached") and answered by FENCE_ACTION (ArduCopter's ``Copter::fence_check``): on the ground a
  disarm; more than 100 m outside LAND; else RTL or LAND, LAND, BRAKE or LAND. A breach acts once; 20 m
  further out it acts again (the backup fence); "Fence breach cleared" once back inside.
* EKF (FS_EKF_THRESH, FS_EKF_ACTION): the estimator's position variance over threshold, or its position
  unusable after a fault, for 1 s -> "EKF variance" and LAND (:mod:`.ekf_check`).

Every action is announced by STATUSTEXT and carried out by ``modes.set_mode``, so it shows in the
mode. As in ArduCopter, a failsafe does not switch a vehicle that is already landing to RTL, and an
armed vehicle still on the ground is disarmed instead. SmartRTL and DO_LAND_START options, which the
model lacks, fall back to RTL; "terminate" falls back to LAND.

Every timer here (FS_GCS_TIMEOUT, BATT_LOW_TIMER, the EKF check's second) counts simulated time, the
vehicle clock, as ArduCopter SITL's ``AP_HAL::millis()`` does; the mission protocol's timeouts follow the
same rule (``docs/conformance.md``, "Time bases").

Deviation from ArduCopter's defaults: BATT_FS_LOW_ACT defaults to RTL and BATT_FS_CRT_ACT to LAND (the
model's battery failsafe is on out of the box), and the voltage thresholds default to 3.5 V and 3.4 V
per cell of the airframe's pack. SIM_BATT_CAP_AH (ArduPilot SITL's name) sets the simulated pack's
capacity, which makes battery tests fast.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from autopilot_model.modules.ekf_check import EkfCheck
from autopilot_model.modules.fence import GIVE_UP_DISTANCE_M, Fence, fence_names
from autopilot_model.modules.mission import MissionStore

if TYPE_CHECKING:
    from autopilot_model.modules.flight_modes import FlightModes
    from autopilot_model.modules.vehicle_api import GroundLink, VehicleApi
    from autopilot_model.params import ParamStore

log = logging.getLogger(__name__)

# ArduCopter custom modes used here
AUTO = 3
RTL = 6
LAND = 9
BRAKE = 17
MODE_NAMES = {RTL: "RTL", LAND: "LAND", BRAKE: "BRAKE"}

_LANDED_ON_GROUND = 1
_LANDED_LANDING = 4
_LANDING_MODES = (LAND,)


def define_safety_params(params: ParamStore, cells: int, capacity_mah: float) -> None:
    """The failsafe parameters (ArduCopter names and units)."""
    params.define("FS_GCS_ENABLE", 0, 0, 7, "int",
                  "GCS failsafe: 0 off, 1 RTL, 2 continue AUTO else RTL, 3 SmartRTL/RTL, 4 SmartRTL/LAND, "
                  "5 LAND, 6 DO_LAND_START/RTL, 7 BRAKE/LAND")
    params.define("FS_GCS_TIMEOUT", 5.0, 2.0, 120.0, doc="GCS heartbeat loss timeout (s)")
    params.define("BATT_LOW_VOLT", round(3.5 * cells, 2), 0.0, 100.0, doc="low battery voltage (V), 0 off")
    params.define("BATT_CRT_VOLT", round(3.4 * cells, 2), 0.0, 100.0,
                  doc="critical battery voltage (V), 0 off")
    params.define("BATT_LOW_TIMER", 10, 0, 120, "int", doc="voltage below a threshold this long (s)")
    params.define("BATT_LOW_MAH", 0, 0, 500000, "int", doc="low battery remaining capacity (mAh), 0 off")
    params.define("BATT_CRT_MAH", 0, 0, 500000, "int", doc="critical remaining capacity (mAh), 0 off")
    params.define("BATT_CAPACITY", round(capacity_mah), 0, 500000, "int", doc="battery capacity (mAh)")
    params.define("BATT_FS_LOW_ACT", 2, 0, 7, "int",
                  "low battery action: 0 none, 1 LAND, 2 RTL, 3 SmartRTL/RTL, 4 SmartRTL/LAND, "
                  "5 terminate, 6 DO_LAND_START/RTL, 7 BRAKE/LAND")
    params.define("BATT_FS_CRT_ACT", 1, 0, 7, "int", "critical battery action (as BATT_FS_LOW_ACT)")
    params.define("SIM_BATT_CAP_AH", round(capacity_mah / 1000.0, 3), 0.001, 1000.0,
                  doc="capacity of the simulated battery (Ah)")

# failsafe action codes -> (mode, fallback)
_FS_ACTIONS: dict[int, tuple[int, int] | None] = {
    0: None, 1: (LAND, LAND), 2: (RTL, LAND), 3: (RTL, LAND), 4: (LAND, LAND), 5: (LAND, LAND),
    6: (RTL, LAND), 7: (BRAKE, LAND),
}
_GCS_ACTIONS: dict[int, tuple[int, int] | None] = {
    0: None, 1: (RTL, LAND), 2: (RTL, LAND), 3: (RTL, LAND), 4: (LAND, LAND), 5: (LAND, LAND),
    6: (RTL, LAND), 7: (BRAKE, LAND),
}
_FENCE_ACTIONS: dict[int, tuple[int, int] | None] = {
    0: None, 1: (RTL, LAND), 2: (LAND, LAND), 3: (RTL, LAND), 4: (BRAKE, LAND), 5: (LAND, LAND),
}


class Safety:
    """GCS-loss, battery and geofence failsafes of one vehicle; :meth:`periodic` at 10 Hz (core).

    ``modes`` is the FlightModes object (``mode``, ``set_mode(mode, reason)``); ``store`` (optional) is
    the :class:`MissionStore` whose FENCE plan gives the polygon fence.
    """

    def __init__(self, vehicle: VehicleApi, endpoint: GroundLink, modes: FlightModes,
                 store: MissionStore | None = None) -> None:
        self.vehicle = vehicle
        self.endpoint = endpoint
        self.modes = modes
        self.store = store
        self.params = vehicle.params
        battery = vehicle.battery
        define_safety_params(self.params, battery.cells, battery.capacity_mah)
        battery.set_capacity(self.params.get("SIM_BATT_CAP_AH") * 1000.0)
        self.params.subscribe("SIM_BATT_CAP_AH", lambda _n, v: battery.set_capacity(v * 1000.0))
        self.gcs_failsafe = False
        self.battery_level = 0
        """0 ok, 1 low, 2 critical (latched)."""
        self.events: list[str] = []
        """Every failsafe text announced, in order (tests and logs)."""
        self._low_since: float | None = None
        self._crit_since: float | None = None
        self.fence = Fence(vehicle, store)
        vehicle.nav.prearm_checks.append(self.fence.prearm_failure)
        self.ekf = EkfCheck(vehicle, modes, self._announce)
        self.on_fence_breach: Callable[[], None] | None = None
        """Called on a new breach while armed (the endpoint sends FENCE_STATUS at once, as ArduPilot)."""

    @property
    def ekf_failsafe(self) -> bool:
        """The EKF failsafe is on."""
        return self.ekf.failsafe

    # --- periodic ---------------------------------------------------------------------------------
    def periodic(self) -> None:
        """Check every failsafe once (10 Hz, core group)."""
        now = float(self.vehicle.clock.now())
        self._check_gcs(now)
        self._check_battery(now)
        self._check_fence()
        self.ekf.periodic(now)

    # --- GCS heartbeat ----------------------------------------------------------------------------
    def _check_gcs(self, now: float) -> None:
        last = self.endpoint.last_gcs_heartbeat_s
        enable = int(self.params.get("FS_GCS_ENABLE"))
        if last is None:
            return
        lost = now - last > self.params.get("FS_GCS_TIMEOUT")
        if not lost:
            if self.gcs_failsafe:
                self.gcs_failsafe = False
                self._announce(mavlink.MAV_SEVERITY_INFO, "GCS Failsafe Cleared")
            return
        if self.gcs_failsafe or enable == 0 or not self.vehicle.nav.armed:
            return
        self.gcs_failsafe = True
        if enable == 2 and self.modes.mode == AUTO:  # "continue with the mission in AUTO"
            self._announce(mavlink.MAV_SEVERITY_CRITICAL, "GCS Failsafe: continuing mission")
            return
        self._act(_GCS_ACTIONS.get(enable), "GCS Failsafe")

    # --- battery ----------------------------------------------------------------------------------
    def _check_battery(self, now: float) -> None:
        p = self.params
        voltage = float(self.vehicle.battery_voltage or self.vehicle.battery.voltage)
        consumed = float(self.vehicle.battery.consumed_mah)
        remaining = p.get("BATT_CAPACITY") - consumed
        timer = p.get("BATT_LOW_TIMER")

        def below(volt_param: str, since: float | None) -> tuple[bool, float | None]:
            thr = p.get(volt_param)
            if thr <= 0 or voltage <= 0 or voltage >= thr:
                return False, None
            since = now if since is None else since
            return now - since >= timer, since

        crit_v, self._crit_since = below("BATT_CRT_VOLT", self._crit_since)
        low_v, self._low_since = below("BATT_LOW_VOLT", self._low_since)
        crit_mah = p.get("BATT_CRT_MAH") > 0 and remaining < p.get("BATT_CRT_MAH")
        low_mah = p.get("BATT_LOW_MAH") > 0 and remaining < p.get("BATT_LOW_MAH")
        level = 2 if (crit_v or crit_mah) else 1 if (low_v or low_mah) else 0
        if level <= self.battery_level:
            return
        self.battery_level = level
        name = "critical" if level == 2 else "low"
        text = f"Battery 1 is {name} {voltage:.2f}V used {consumed:.0f} mAh"
        if not self.vehicle.nav.armed:
            self._announce(mavlink.MAV_SEVERITY_CRITICAL, text)
            return
        act = int(p.get("BATT_FS_CRT_ACT" if level == 2 else "BATT_FS_LOW_ACT"))
        self._act(_FS_ACTIONS.get(act), text)

    # --- geofence ---------------------------------------------------------------------------------
    @property
    def fence_breached(self) -> int:
        """FENCE_TYPE bits currently breached."""
        return self.fence.breached

    def fence_excess(self) -> tuple[int, float]:
        """(breached FENCE_TYPE bits, metres beyond the furthest breached fence) at the last check."""
        bits = self.fence.breached
        return bits, max(0.0, self.fence.breach_distance(bits)) if bits else 0.0

    def _check_fence(self) -> None:
        """ArduCopter's ``fence_checks_async`` and ``fence_check``."""
        nav = self.vehicle.nav
        fence = self.fence
        landed = nav.landed_state == _LANDED_ON_GROUND
        landing = self.modes.mode in _LANDING_MODES or nav.landed_state == _LANDED_LANDING
        before = fence.breached
        new = fence.check(landing or landed or not nav.armed)
        if fence.floor_auto_enabled:
            fence.floor_auto_enabled = False
            self._announce(mavlink.MAV_SEVERITY_NOTICE, "Min Alt fence enabled (auto enable)")
        if not new and before and not fence.breached and not landed:
            self._announce(mavlink.MAV_SEVERITY_NOTICE, "Fence breach cleared")
        if new and self.on_fence_breach is not None:
            self.on_fence_breach()
        if not nav.armed or not new:
            return
        if not landed:
            self._announce(mavlink.MAV_SEVERITY_NOTICE, f"{fence_names(new)} breached")
        action = int(self.params.get("FENCE_ACTION"))
        if action == 0:
            return
        if landed:
            nav.disarm()
            return
        if fence.breach_distance(new) > GIVE_UP_DISTANCE_M:
            self.modes.set_mode(LAND, "fence breach")
            return
        mode, fallback = _FENCE_ACTIONS.get(action) or (RTL, LAND)
        if not self.modes.set_mode(mode, "fence breach")[0] and fallback != mode:
            self.modes.set_mode(fallback, "fence breach")

    # --- actions ----------------------------------------------------------------------------------
    def _announce(self, severity: int, text: str) -> None:
        self.events.append(text)
        log.warning(text)
        self.endpoint.statustext(severity, text)

    def _act(self, action: tuple[int, int] | None, why: str) -> None:
        """Carry out a failsafe action (mode, fallback), announcing it."""
        nav = self.vehicle.nav
        if action is None:
            self._announce(mavlink.MAV_SEVERITY_CRITICAL, why)
            return
        if nav.landed_state == _LANDED_ON_GROUND:
            nav.disarm()
            self._announce(mavlink.MAV_SEVERITY_CRITICAL, f"{why}: on the ground, disarming")
            return
        mode, fallback = action
        current = self.modes.mode
        if current in _LANDING_MODES or (current == mode and mode != BRAKE):
            name = MODE_NAMES.get(current, str(current))
            self._announce(mavlink.MAV_SEVERITY_CRITICAL, f"{why}: continuing {name}")
            return
        ok, reason = self.modes.set_mode(mode, why)
        if not ok and fallback != mode:
            log.warning("%s: %s denied (%s), trying %s", why, MODE_NAMES[mode], reason, MODE_NAMES[fallback])
            mode = fallback
            ok, reason = self.modes.set_mode(mode, why)
        if ok:
            self._announce(mavlink.MAV_SEVERITY_CRITICAL, f"{why}: {MODE_NAMES[mode]}")
        else:
            self._announce(mavlink.MAV_SEVERITY_CRITICAL, f"{why}: no action possible ({reason})")
