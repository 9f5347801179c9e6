"""Differential conformance of pilot input: sticks over MAVLink, model vs ArduCopter SITL.

:func:`pilot_support.observe_pilot` flies one pilot's scenario (RC_CHANNELS_OVERRIDE and MANUAL_CONTROL
in STABILIZE, LOITER, ALT_HOLD and POSHOLD, then silence: the RC failsafe) on each autopilot; every
check states what ArduCopter does (ArduCopter V4.7.0-dev SITL with ``SIM_RC_FAIL=1``) and holds it
against each in turn. The model's half always runs; ArduCopter's with ``TASKFLIGHT_ARDUCOPTER``.
Differences kept on purpose are in ``docs/conformance.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from harness.differential.pilot import ALT_HOLD, LOITER, POSHOLD, RTL, STABILIZE, observe_pilot
from harness.observer import M

pytestmark = pytest.mark.integration

SPEEDUP = 5.0
OBSERVE = observe_pilot  # the seen fixture: the scenario flown on each autopilot


ACCEPTED, FAILED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_FAILED
ON_GROUND, IN_AIR, LANDING = 1, 2, 4


def _forward(o: tuple[float, float], lo: float, hi: float) -> bool:
    heading, speed = o
    return abs(heading) < 25.0 and lo <= speed <= hi


CHECKS: dict[str, tuple[str, Callable[[dict[str, Any]], bool]]] = {
    "intervals": ("SET_MESSAGE_INTERVAL EXTENDED_SYS_STATE, RC_CHANNELS, SERVO_OUTPUT_RAW: ACCEPTED",
                  lambda o: o["intervals"] == [ACCEPTED] * 3),
    "rc_channels": ("RC_CHANNELS shows the override (1500, 1500, 1000, 1500), chancount >= 4",
                    lambda o: o["rc_channels"] == (1500, 1500, 1000, 1500, True)),
    "servo_disarmed": ("SERVO_OUTPUT_RAW 1000 us on the four motors while disarmed",
                       lambda o: o["servo_disarmed"] == (1000, 1000, 1000, 1000)),
    "servo_hover": ("motor outputs between 1100 and 1900 us in a hover",
                    lambda o: all(1100 < s < 1900 for s in o["servo_hover"])),
    "arm_throttle_high_stabilize": ("FAILED (Throttle too high)",
                                    lambda o: o["arm_throttle_high_stabilize"] == FAILED),
    "set_loiter": ("ACCEPTED", lambda o: o["set_loiter"] == ACCEPTED),
    "arm_loiter": ("ACCEPTED with the throttle down", lambda o: o["arm_loiter"] == ACCEPTED),
    "climb_stops_at_mid_stick": ("throttle above mid-stick takes off and climbs; mid-stick holds",
                                 lambda o: o["climb_stops_at_mid_stick"]),
    "loiter_hold_alt": ("LOITER at mid-stick holds the altitude within 1 m over 3 s",
                        lambda o: o["loiter_hold_alt_change_m"] < 1.0),
    "loiter_pitch_fwd": ("pitch 1300 us for 6 s: forward within 25 deg of the heading at 2-6 m/s",
                         lambda o: _forward(o["loiter_pitch_fwd"], 2.0, 6.0)),
    "loiter_stop": ("sticks centred: below 0.3 m/s within 12 s", lambda o: o["loiter_stop_s"] < 12.0),
    "manual_roll_right": ("MANUAL_CONTROL y=500 for 5 s: to the right (90 +- 25 deg) at 1.5-6 m/s",
                          lambda o: abs(o["manual_roll_right"][0] - 90.0) < 25.0
                          and 1.5 <= o["manual_roll_right"][1] <= 6.0),
    "set_alt_hold": ("ACCEPTED", lambda o: o["set_alt_hold"] == ACCEPTED),
    "alt_hold_alt": ("ALT_HOLD at mid-stick holds the altitude within 1 m over 3 s",
                     lambda o: o["alt_hold_alt_change_m"] < 1.0),
    "alt_hold_climb": ("throttle 1900 us: climbs at 1-2.6 m/s after 2 s (PILOT_SPEED_UP 2.5 m/s at full)",
                       lambda o: 1.0 <= o["alt_hold_climb_mps"] <= 2.6),
    "set_poshold": ("ACCEPTED", lambda o: o["set_poshold"] == ACCEPTED),
    "poshold_pitch_fwd": ("pitch 1300 us for 4 s: forward within 25 deg of the heading at 2-12 m/s",
                          lambda o: _forward(o["poshold_pitch_fwd"], 2.0, 12.0)),
    "poshold_stop": ("sticks centred: below 0.3 m/s within 15 s", lambda o: o["poshold_stop_s"] < 15.0),
    "failsafe": ("override silent: RTL after RC_FS_TIMEOUT (2 s here), within 4 s",
                 lambda o: o["failsafe_after_s"] < 4.0),
    "failsafe_text": ("a STATUSTEXT naming the radio failsafe", lambda o: o["rc_failsafe_text"]),
    "modes": ("STABILIZE, LOITER, ALT_HOLD, POSHOLD, RTL",
              lambda o: o["modes"] == [STABILIZE, LOITER, ALT_HOLD, POSHOLD, RTL]),
    "landed_states": ("ON_GROUND first and last, IN_AIR, LANDING before the end",
                      lambda o: o["landed_states"][0] == ON_GROUND and o["landed_states"][-1] == ON_GROUND
                      and IN_AIR in o["landed_states"] and o["landed_states"][-2] == LANDING),
}


@pytest.mark.parametrize("check", list(CHECKS))
def test_the_pilot_sees_what_arducopter_shows(seen: dict[str, Any], check: str) -> None:
    expected, holds = CHECKS[check]
    assert holds(seen), f"{check}: ArduCopter shows {expected}; observed {seen}"
