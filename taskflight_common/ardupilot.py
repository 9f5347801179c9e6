"""ArduCopter's numbers that every side of the project speaks: its flight modes.

The custom mode of a HEARTBEAT (``custom_mode``) and of MAV_CMD_DO_SET_MODE / SET_MODE is one of
these numbers (ArduCopter ``mode.h``, ``enum class Mode::Number``). The autopilot model flies a subset
of them (:data:`autopilot_model.modules.flight_modes.MODE_NAMES`); the companion and the tests name
them through this enum, so no number is written twice.
"""

from __future__ import annotations

from enum import IntEnum


class CopterMode(IntEnum):
    """ArduCopter flight mode numbers (``Mode::Number``)."""

    STABILIZE = 0
    ACRO = 1
    ALT_HOLD = 2
    AUTO = 3
    GUIDED = 4
    LOITER = 5
    RTL = 6
    CIRCLE = 7
    LAND = 9
    DRIFT = 11
    SPORT = 13
    FLIP = 14
    AUTOTUNE = 15
    POSHOLD = 16
    BRAKE = 17
    THROW = 18
    AVOID_ADSB = 19
    GUIDED_NOGPS = 20
    SMART_RTL = 21
    FLOWHOLD = 22
    FOLLOW = 23
    ZIGZAG = 24
    SYSTEMID = 25
    AUTOROTATE = 26
    AUTO_RTL = 27


#: custom_mode number -> ArduCopter's name of it (what a ground station shows).
COPTER_MODE_NAMES: dict[int, str] = {m.value: m.name for m in CopterMode}
