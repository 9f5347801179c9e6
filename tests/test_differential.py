"""Differential conformance: one ground-station scenario against the model and against ArduCopter SITL.

:func:`differential_support.observe` flies the same pymavlink scenario on each
autopilot; every check below states what ArduCopter does (measured on ArduCopter V4.7.0-dev SITL,
see ``docs/conformance.md``) and holds it against each autopilot in turn: the model's half runs
everywhere, ArduCopter's half with ``TASKFLIGHT_ARDUCOPTER`` (else it skips, saying why). A check
that fails on the model but passes on ArduCopter is a fidelity bug of the model. The differences
kept on purpose are listed, with their reasons, in ``docs/conformance.md`` and not asserted here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import pytest

from harness.differential.basics import OLD_PARAMS, observe
from harness.observer import GUIDED, LAND, STABILIZE, M

pytestmark = pytest.mark.integration

SPEEDUP = 8.0
OBSERVE = observe  # the seen fixture: the scenario flown on each autopilot


ACCEPTED, FAILED, UNSUPPORTED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_FAILED, M.MAV_RESULT_UNSUPPORTED
ON_GROUND, TAKEOFF, IN_AIR, LANDING = 1, 3, 2, 4

#: check name -> (what ArduCopter does, the predicate on the observations)
CHECKS: dict[str, tuple[str, Callable[[dict[str, Any]], bool]]] = {
    "heartbeat": ("MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_ARDUPILOTMEGA",
                  lambda o: o["heartbeat"] == (M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA)),
    "initial_mode": ("STABILIZE", lambda o: o["initial_mode"] == STABILIZE),
    "local_position_at_start": ("within 0.5 m of the EKF origin",
                                lambda o: math.dist(o["local_position_at_start"], (0, 0, 0)) < 0.5),
    "takeoff_disarmed": ("FAILED", lambda o: o["takeoff_disarmed"] == FAILED),
    "unknown_mode": ("FAILED (and 'No such mode')", lambda o: o["unknown_mode"] == FAILED),
    "unknown_command": ("UNSUPPORTED", lambda o: o["unknown_command"] == UNSUPPORTED),
    "set_guided": ("ACCEPTED", lambda o: o["set_guided"] == ACCEPTED),
    "request_home": ("ACCEPTED, then HOME_POSITION", lambda o: o["request_home"] == ACCEPTED),
    "home_xyz": ("x, y, z = 0", lambda o: o["home_xyz"] == (0.0, 0.0, 0.0)),
    "home_q": ("q = NaN", lambda o: o["home_q_nan"]),
    "param_names": ("all of differential_support.PARAMS",
                    lambda o: all(o["params"][n] is not None for n in o["params"] if n not in OLD_PARAMS)),
    "old_param_names": ("SYSID_THISMAV, SYSID_MYGCS unknown",
                        lambda o: all(o["params"][n] is None for n in OLD_PARAMS)),
    "param_defaults": ("GUID_TIMEOUT 3, FS_GCS_ENABLE 0, FS_GCS_TIMEOUT 5, DISARM_DELAY 10, LAND_SPEED 50, "
                       "RTL_ALT 1500, MAV_SYSID 1, MAV_GCS_SYSID 255, PSC_VELXY_FLTE 5, PSC_VELXY_FLTD 5",
                       lambda o: all(o["params"][n] == v for n, v in (
                           ("GUID_TIMEOUT", 3.0), ("FS_GCS_ENABLE", 0.0), ("FS_GCS_TIMEOUT", 5.0),
                           ("DISARM_DELAY", 10.0), ("LAND_SPEED", 50.0), ("RTL_ALT", 1500.0),
                           ("MAV_SYSID", 1.0), ("MAV_GCS_SYSID", 255.0), ("PSC_VELXY_FLTE", 5.0),
                           ("PSC_VELXY_FLTD", 5.0)))),
    "arm_in_guided": ("ACCEPTED once the pre-arm checks pass", lambda o: o["arm"] == ACCEPTED),
    "takeoff": ("ACCEPTED", lambda o: o["takeoff"] == ACCEPTED),
    "takeoff_again_on_the_ground": ("ACCEPTED while still on the ground (FAILED once the land detector "
                                    "has cleared)", lambda o: o["takeoff_again_on_the_ground"] == ACCEPTED),
    "disarm_in_the_air": ("FAILED", lambda o: o["disarm_in_the_air"] == FAILED),
    "landed_states": ("ON_GROUND, TAKEOFF, IN_AIR, LANDING, ON_GROUND",
                      lambda o: o["landed_states"] == [ON_GROUND, TAKEOFF, IN_AIR, LANDING, ON_GROUND]),
    "modes": ("STABILIZE, GUIDED, LAND", lambda o: o["modes"] == [STABILIZE, GUIDED, LAND]),
    "guid_timeout": ("slows below 1 m/s 3.0-4.5 s after the last velocity target",
                     lambda o: 3.0 <= o["guid_timeout_slowed_s"] <= 4.5),
    "guid_timeout_travel": ("5-10 m travelled after the last target at 2 m/s",
                            lambda o: 5.0 <= o["guid_timeout_travel_m"] <= 10.0),
    "land": ("ACCEPTED; lands and disarms", lambda o: o["land"] == ACCEPTED),
    "mission_upload": ("items 0, 1, 2 requested in order; MAV_MISSION_ACCEPTED",
                       lambda o: o["mission_requested_seqs"] == [0, 1, 2] and o["mission_ack"] == 0),
    "mission_request_type": ("MISSION_REQUEST or MISSION_REQUEST_INT (ArduCopter: MISSION_REQUEST)",
                             lambda o: o["mission_request_type"] in ("MISSION_REQUEST",
                                                                     "MISSION_REQUEST_INT")),
    "mission_count": ("3 (home is item 0)", lambda o: o["mission_count"] == 3),
}


@pytest.mark.parametrize("check", list(CHECKS))
def test_the_ground_station_sees_what_arducopter_shows(seen: dict[str, Any], check: str) -> None:
    expected, holds = CHECKS[check]
    assert holds(seen), f"{check}: ArduCopter shows {expected}; observed {seen}"
