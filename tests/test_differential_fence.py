"""Differential conformance of the fence and the status messages: model vs ArduCopter SITL.

:func:`fence_support.observe_fence` runs one ground station's scenario on each autopilot: DO_FENCE_ENABLE,
FENCE_STATUS, the pre-arm fence checks, GUIDED targets beyond the fence, a breach (the circle pulled in
under the vehicle) and the RTL that follows, EKF_STATUS_REPORT, NAV_CONTROLLER_OUTPUT, GPS_GLOBAL_ORIGIN
(presence and rates), AUTOPILOT_VERSION against the parameter names, the parameters QGroundControl reads,
SETUP_SIGNING. Every check states what ArduCopter does (V4.7.0-dev SITL) and holds it against each
autopilot; ArduCopter's half runs with ``TASKFLIGHT_ARDUCOPTER``. Differences kept on purpose are in
``docs/conformance.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from harness.differential.fence import QGC_PARAMS, RATE_HZ, SYSTEM_TIME_HZ, observe_fence
from harness.observer import GUIDED, RTL, STABILIZE, M

pytestmark = pytest.mark.integration

SPEEDUP = 8.0
OBSERVE = observe_fence  # the seen fixture: the scenario flown on each autopilot


ACCEPTED, FAILED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_FAILED
BOUNDARY = M.FENCE_BREACH_BOUNDARY
HOME = (-35.363261, 149.165230, 584.0)


def _rate_ok(counts: dict[str, int], name: str) -> bool:
    """``name`` arrived at RATE_HZ +- 30 %, judged against SYSTEM_TIME's count in the same window."""
    seconds = counts["SYSTEM_TIME"] / SYSTEM_TIME_HZ
    return seconds >= 3 and abs(counts[name] / seconds - RATE_HZ) <= 0.3 * RATE_HZ


def _toward_north(bearing: int, wp_dist: int, x: float) -> bool:
    return min(bearing % 360, 360 - bearing % 360) <= 20 and abs(wp_dist - (40 - x)) <= 3


CHECKS: dict[str, tuple[str, Callable[[dict[str, Any]], bool]]] = {
    "intervals": ("SET_MESSAGE_INTERVAL of EXTENDED_SYS_STATE, SYSTEM_TIME, FENCE_STATUS, EKF_STATUS_REPORT, "
                  "NAV_CONTROLLER_OUTPUT, GPS_GLOBAL_ORIGIN: ACCEPTED",
                  lambda o: o["intervals"] == [ACCEPTED] * 6),
    "version": ("AUTOPILOT_VERSION 4.7.x, a development build, since it names the system id MAV_SYSID",
                lambda o: o["version"][:2] >= (4, 7) and o["params"]["MAV_SYSID"] == 1
                and o["params"]["SYSID_THISMAV"] is None),
    "qgc_params": ("every parameter QGroundControl's ArduCopter plugin reads is present",
                   lambda o: [n for n in QGC_PARAMS if o["params"][n] is None] == []),
    "param_defaults": ("FRAME_CLASS 1, FENCE_TYPE 7, FENCE_ALT_MAX 100, FENCE_ALT_MIN -10, FENCE_MARGIN 2, "
                       "FENCE_ACTION 1, RTL_ALT 1500, RTL_ALT_FINAL 0, BATT_MONITOR 4, ARMING_CHECK 1",
                       lambda o: [o["params"][n] for n in ("FRAME_CLASS", "FENCE_TYPE", "FENCE_ALT_MAX",
                                                           "FENCE_ALT_MIN", "FENCE_MARGIN", "FENCE_ACTION",
                                                           "RTL_ALT", "RTL_ALT_FINAL", "BATT_MONITOR",
                                                           "ARMING_CHECK")]
                       == [1, 7, 100, -10, 2, 1, 1500, 0, 4, 1]),
    "ekf": ("EKF_STATUS_REPORT: attitude, velocities, positions (flags 0x33F), variances below 0.5",
            lambda o: o["ekf"][0] & 0x33F == 0x33F and max(o["ekf"][1:]) < 0.5),
    "origin": ("GPS_GLOBAL_ORIGIN at the start position (within 1e-5 deg, 1 m)",
               lambda o: abs(o["origin"][0] - HOME[0]) < 1e-5 and abs(o["origin"][1] - HOME[1]) < 1e-5
               and abs(o["origin"][2] - HOME[2]) < 1.0),
    "no_fence_status_while_disabled": ("no FENCE_STATUS while no fence is enabled",
                                       lambda o: o["rates_fence_off"]["FENCE_STATUS"] == 0
                                       and o["rates_fence_disabled"]["FENCE_STATUS"] == 0),
    "rates": ("EKF_STATUS_REPORT, NAV_CONTROLLER_OUTPUT, GPS_GLOBAL_ORIGIN at the rate asked (2 Hz +- 30 %)",
              lambda o: all(_rate_ok(o["rates_fence_off"], t)
                            for t in ("EKF_STATUS_REPORT", "NAV_CONTROLLER_OUTPUT", "GPS_GLOBAL_ORIGIN"))),
    "fence_status_rate": ("FENCE_STATUS at 2 Hz +- 30 % while enabled",
                          lambda o: _rate_ok(o["rates_flying"], "FENCE_STATUS")),
    "disarm_on_ground": ("ACCEPTED", lambda o: o["disarm_on_ground"] == ACCEPTED),
    "fence_enable_bad_action": ("DO_FENCE_ENABLE param1 5: FAILED",
                                lambda o: o["fence_enable_bad_action"] == FAILED),
    "fence_enable_floor_unconfigured": ("DO_FENCE_ENABLE of the floor alone, not in FENCE_TYPE: FAILED",
                                        lambda o: o["fence_enable_floor_unconfigured"] == FAILED),
    "fence_enable": ("DO_FENCE_ENABLE 1: ACCEPTED", lambda o: o["fence_enable"] == ACCEPTED),
    "fence_status_enabled": ("FENCE_STATUS 0 breaches, count 0, type NONE",
                             lambda o: o["fence_status_enabled"] == (0, 0, 0)),
    "sys_status_fence": ("SYS_STATUS geofence present, enabled, healthy",
                         lambda o: o["sys_status_fence"] == (True, True, True)),
    "prearm_alt_order": ("arming FAILED, 'PreArm: FENCE_ALT_MAX < FENCE_ALT_MIN'",
                         lambda o: o["prearm_alt_order"][0] == FAILED
                         and "FENCE_ALT_MAX < FENCE_ALT_MIN" in (o["prearm_alt_order"][1] or "")),
    "prearm_margin": ("arming FAILED, 'PreArm: FENCE_MARGIN too big'",
                      lambda o: o["prearm_margin"][0] == FAILED
                      and "FENCE_MARGIN too big" in (o["prearm_margin"][1] or "")),
    "fly": ("GUIDED, arm, take-off: ACCEPTED",
            lambda o: (o["set_guided"], o["arm"], o["takeoff"]) == (ACCEPTED,) * 3),
    "setup_signing_armed": ("SETUP_SIGNING while armed: refused, 'ERROR: Won't setup signing when armed'",
                            lambda o: "Won't setup signing when armed" in o["setup_signing_armed"]),
    "target_outside_circle": ("a position target beyond FENCE_RADIUS is ignored: moved < 1.5 m in 3 s",
                              lambda o: o["target_outside_circle_moved_m"] < 1.5),
    "target_above_ceiling": ("a position target above FENCE_ALT_MAX is ignored: climbed < 1 m in 3 s",
                             lambda o: o["target_above_ceiling_climbed_m"] < 1.0),
    "reposition_outside": ("DO_REPOSITION beyond the fence: FAILED",
                           lambda o: o["reposition_outside"] == FAILED),
    "nav_controller_en_route": ("NAV_CONTROLLER_OUTPUT toward a target 40 m north: bearing 0 +- 20 deg, "
                                "wp_dist within 3 m of the distance left",
                                lambda o: _toward_north(*o["nav_controller_en_route"])),
    "fence_status_breached": ("FENCE_STATUS on the breach: breached, count 1, BOUNDARY, its time",
                              lambda o: o["fence_status_breached"] == (1, 1, BOUNDARY, True)),
    "fence_status_cleared": ("back inside: not breached, count still 1, type NONE",
                             lambda o: o["fence_status_cleared"] == (0, 1, 0)),
    "breach_texts": ("'Circle fence breached', then 'Fence breach cleared'",
                     lambda o: "Circle fence breached" in o["breach_texts"]
                     and "Fence breach cleared" in o["breach_texts"]),
    "modes_after_breach": ("GUIDED, then RTL (which lands and disarms)",
                           lambda o: o["modes_after_breach"] == [GUIDED, RTL]),
    "modes": ("STABILIZE, GUIDED, RTL", lambda o: o["modes"] == [STABILIZE, GUIDED, RTL]),
    "fence_disable": ("DO_FENCE_ENABLE 0: ACCEPTED", lambda o: o["fence_disable"] == ACCEPTED),
    "signing_required": ("after SETUP_SIGNING an unsigned command is ignored (no ACK)",
                         lambda o: o["unsigned_after_setup"] is None),
    "signed": ("a command signed with the key: ACCEPTED", lambda o: o["signed"] == ACCEPTED),
    "signing_off": ("SETUP_SIGNING with a zero key: unsigned commands ACCEPTED again",
                    lambda o: o["unsigned_after_off"] == ACCEPTED),
}


@pytest.mark.parametrize("check", list(CHECKS))
def test_the_ground_station_sees_what_arducopter_shows(seen: dict[str, Any], check: str) -> None:
    expected, holds = CHECKS[check]
    assert holds(seen), f"{check}: ArduCopter shows {expected}; observed {seen}"
