"""The EKF failsafe, as ArduCopter's ``Copter::ekf_check`` and ``failsafe_ekf_event`` (ekf_check.cpp).

Run at 10 Hz by :class:`~autopilot_model.modules.safety.Safety`:

* nothing until the estimator has an origin (its first initialisation); disarmed, or FS_EKF_THRESH 0,
  the check is reset and the failsafe cleared;
* "over threshold" when the estimator's normalised position innovation (``pos_variance``, the square
  root of its test ratio, what ArduPilot's ``get_variances`` reports) reaches FS_EKF_THRESH, or when
  its position is not usable (``position_ok`` false: re-converging after a filter fault such as a
  non-finite state). ArduCopter counts two of compass, velocity and position variance; the model's
  estimator has the position test only, so that one counts alone;
* ten checks over threshold in a row (1 s, EKF_CHECK_ITERATIONS_MAX) latch "bad variance": STATUSTEXT
  "EKF variance" (CRITICAL, at most every 30 s) and the failsafe event; each check under threshold
  counts down, and at zero the latch and the failsafe clear;
* the event: nothing more in a mode that needs no position (STABILIZE, ALT_HOLD, LAND) unless
  FS_EKF_ACTION is 3; otherwise LAND (FS_EKF_ACTION 1, the default, and 3) or ALT_HOLD (2, LAND if
  refused).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from autopilot_model.modules.flight_modes import ALT_HOLD, AUTO, BRAKE, GUIDED, LAND, LOITER, RTL, FlightModes

if TYPE_CHECKING:
    from autopilot_model.modules.vehicle_api import VehicleApi
    from autopilot_model.params import ParamStore

log = logging.getLogger(__name__)

EKF_CHECK_ITERATIONS_MAX = 10
"""Checks at 10 Hz over threshold before the failsafe (1 s), as ArduCopter."""
EKF_CHECK_WARNING_TIME_S = 30.0
""""EKF variance" is sent at most this often."""

REQUIRES_POSITION = frozenset({AUTO, GUIDED, LOITER, RTL, BRAKE})
"""Modes for which ArduCopter's ``requires_GPS()`` is true (of those the model has)."""

FS_EKF_ACTION_LAND = 1
FS_EKF_ACTION_ALTHOLD = 2
FS_EKF_ACTION_LAND_EVEN_STABILIZE = 3


def define_ekf_params(params: ParamStore) -> None:
    """FS_EKF_ACTION and FS_EKF_THRESH (ArduCopter names, values and defaults)."""
    params.define("FS_EKF_ACTION", FS_EKF_ACTION_LAND, 1, 3, "int",
                  "EKF failsafe action: 1 LAND, 2 ALT_HOLD, 3 LAND even in STABILIZE")
    params.define("FS_EKF_THRESH", 0.8, 0.0, 1.0,
                  doc="EKF failsafe variance threshold: 0.6 strict, 0.8 default, 1.0 relaxed, 0 off")


class EkfCheck:
    """ArduCopter's EKF check and failsafe for one vehicle; see the module docstring."""

    def __init__(self, vehicle: VehicleApi, modes: FlightModes, announce: Callable[[int, str], None]) -> None:
        self.vehicle = vehicle
        self.modes = modes
        self.params = vehicle.params
        self._announce = announce
        define_ekf_params(self.params)
        self.fail_count = 0
        self.bad_variance = False
        self.failsafe = False
        """The EKF failsafe is on (ArduCopter's ``failsafe.ekf``)."""
        self._has_origin = False
        self._last_warn_s = -EKF_CHECK_WARNING_TIME_S

    def periodic(self, now: float) -> None:
        """One check (10 Hz)."""
        est = getattr(self.vehicle, "estimator", None)
        if est is None:
            return
        self._has_origin = self._has_origin or bool(est.initialised)
        if not self._has_origin:
            return
        thresh = self.params.get("FS_EKF_THRESH")
        if not self.vehicle.nav.armed or thresh <= 0.0:
            self.fail_count = 0
            self.bad_variance = False
            self._off()
            return
        if est.pos_variance >= thresh or not est.position_ok:
            if not self.bad_variance:
                self.fail_count += 1
                if self.fail_count >= EKF_CHECK_ITERATIONS_MAX:
                    self.fail_count = EKF_CHECK_ITERATIONS_MAX
                    self.bad_variance = True
                    if now - self._last_warn_s > EKF_CHECK_WARNING_TIME_S:
                        self._announce(mavlink.MAV_SEVERITY_CRITICAL, "EKF variance")
                        self._last_warn_s = now
                    self._event()
        elif self.fail_count > 0:
            self.fail_count -= 1
            if self.bad_variance and self.fail_count == 0:
                self.bad_variance = False
                self._off()

    def _event(self) -> None:
        """ArduCopter's ``failsafe_ekf_event``."""
        if self.failsafe:
            return
        self.failsafe = True
        log.warning("EKF failsafe")
        mode = self.modes.mode
        action = int(self.params.get("FS_EKF_ACTION"))
        if mode == LAND:
            return
        if mode not in REQUIRES_POSITION and action != FS_EKF_ACTION_LAND_EVEN_STABILIZE:
            return
        if action == FS_EKF_ACTION_ALTHOLD and self.modes.set_mode(ALT_HOLD, "EKF failsafe")[0]:
            return
        self.modes.set_mode(LAND, "EKF failsafe")

    def _off(self) -> None:
        """ArduCopter's ``failsafe_ekf_off_event`` (logged only: ArduCopter sends no text)."""
        if self.failsafe:
            self.failsafe = False
            log.info("EKF failsafe cleared")
