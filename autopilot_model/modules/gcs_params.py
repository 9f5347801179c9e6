"""The ArduCopter parameters QGroundControl reads when it connects, which no flying module of the model owns.

QGroundControl's ArduCopter plugin builds its setup pages from parameters (``APMAirframeComponent``,
``APMFlightModesComponent``, ``APMRadioComponent``, ``APMSensorsComponent``, ``APMPowerComponent``,
``APMSafetyComponent``); one it asks for and cannot find is reported as "missing parameters". The
parameters that drive the model (GUID_TIMEOUT, FS_*, BATT_*, FENCE_*, RTL_ALT, LAND_SPEED, WPNAV_*, RC1-4,
ATC_*, PSC_*, ...) are declared by the modules that use them; this module declares the rest, with
ArduCopter's names and units, in two kinds:

* *fixed* (the range is the one value the model flies; a PARAM_SET of another value is refused with the
  reason): the frame (FRAME_CLASS 1 quad, FRAME_TYPE 1 X: the airframe file decides), the channel map
  (RCMAP_*), channel reversal, the battery monitor kind, the sensors' ids, orientations and calibration
  offsets (QGC counts the sensors calibrated when the offsets are not zero, as ArduPilot SITL's
  ``copter.parm`` sets them), ARMING_CHECK (all checks, always), RTL_ALT_FINAL 0 (RTL lands) and
  RTL_LOIT_TIME 0 (RTL does not wait above home);
* *stored, not flown* (accepted and persisted, so a ground station's set-up pages work, but no module of
  the model reads them, and ``docs/conformance.md`` says so): the flight-mode switch FLTMODE1-6 /
  FLTMODE_CH, SIMPLE, SUPER_SIMPLE, and channels 5-8's calibration RC5-8_MIN/MAX/TRIM.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autopilot_model.params import ParamStore

#: name -> fixed value (the model flies only this)
FIXED: dict[str, float] = {
    "FRAME_CLASS": 1, "FRAME_TYPE": 1,
    "RCMAP_ROLL": 1, "RCMAP_PITCH": 2, "RCMAP_THROTTLE": 3, "RCMAP_YAW": 4,
    **{f"RC{ch}_REVERSED": 0 for ch in range(1, 9)},
    "BATT_MONITOR": 4,
    "ARMING_CHECK": 1,
    "RTL_ALT_FINAL": 0, "RTL_LOIT_TIME": 0,
    "AHRS_ORIENTATION": 0, "COMPASS_ORIENT": 0, "COMPASS_EXTERNAL": 0,
    "COMPASS_USE": 1, "COMPASS_USE2": 0, "COMPASS_USE3": 0,
    "COMPASS_DEV_ID": 97539, "COMPASS_DEV_ID2": 0, "COMPASS_DEV_ID3": 0,
    "COMPASS_OFS_X": 5, "COMPASS_OFS_Y": 13, "COMPASS_OFS_Z": -18,
    "INS_USE": 1, "INS_USE2": 0, "INS_USE3": 0,
    "INS_ACCOFFS_X": 0.001, "INS_ACCOFFS_Y": 0.001, "INS_ACCOFFS_Z": 0.001,
}
_FLOAT_FIXED = ("COMPASS_OFS", "INS_ACCOFFS")
_INT_FIXED = {n for n in FIXED if not n.startswith(_FLOAT_FIXED)}

#: name -> (default, lo, hi, kind, doc): stored for ground stations, not flown
STORED: dict[str, tuple[float, float, float, str, str]] = {
    **{f"FLTMODE{i}": (0, 0, 30, "int", f"flight mode of switch position {i} (stored, not flown)")
       for i in range(1, 7)},
    "FLTMODE_CH": (5, 0, 16, "int", "flight-mode channel (stored, not flown: the model has no mode switch)"),
    "SIMPLE": (0, 0, 63, "int", "simple-mode bitmask (stored, not flown)"),
    "SUPER_SIMPLE": (0, 0, 63, "int", "super-simple bitmask (stored, not flown)"),
    **{f"RC{ch}_{what}": (dflt, 800, 2200, "int", f"RC channel {ch} {what.lower()} PWM (stored, not flown)")
       for ch in range(5, 9) for what, dflt in (("MIN", 1100), ("MAX", 1900), ("TRIM", 1500))},
}


def define_gcs_params(params: ParamStore) -> None:
    """Declare every parameter above (idempotent: one a module already declared keeps its definition)."""
    for name, value in FIXED.items():
        params.define(name, value, value, value, "int" if name in _INT_FIXED else "float",
                      "fixed: the model flies this value only")
    for name, (default, lo, hi, kind, doc) in STORED.items():
        params.define(name, default, lo, hi, kind, doc)
