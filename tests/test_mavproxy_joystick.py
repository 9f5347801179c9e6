"""MAVProxy drives a joystick flight in LOITER: its ``rc`` command is the pilot's sticks.

MAVProxy (pip package) runs as a pilot types at it: commands on its standard input. ``rc N PWM`` makes
it send RC_CHANNELS_OVERRIDE at 10 Hz (wall time), so the model runs at speedup 2: the override stays
well within RC_FS_TIMEOUT of simulated time. What is checked is what a second ground station
(pymavlink over UDP) observes: the take-off on the throttle, forward flight on the pitch stick, the stop
when it is centred, the descent and landing on the throttle, the disarm after DISARM_DELAY, and
MAVProxy's own view (mode, ARMED) and RC_CHANNELS showing its sticks.
"""

from __future__ import annotations

import math

import pytest

from harness.mavproxy import MavProxy
from harness.observer import Gcs, M
from taskflight_common.ardupilot import CopterMode

pytestmark = pytest.mark.integration

SPEEDUP = 2.0
LOITER = CopterMode.LOITER


def test_mavproxy_flies_loiter_with_rc_sticks(mavproxy: tuple[MavProxy, Gcs]) -> None:
    mp, gcs = mavproxy
    mp.out.wait("Detected vehicle 1:1", 30)
    gcs.request_streams(10)
    gcs.conn.mav.command_long_send(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_RC_CHANNELS,
                                   100_000, 0, 0, 0, 0, 0)
    gcs.wait_prearm(gcs.wall(60))

    def lpn() -> object:
        return gcs.last.get("LOCAL_POSITION_NED")

    mp.type("mode LOITER")
    mp.out.wait("LOITER", 20)
    mp.type("rc 3 1000")
    gcs.wait(lambda: (m := gcs.last.get("RC_CHANNELS")) is not None and m.chan3_raw == 1000, gcs.wall(10),
             "RC_CHANNELS showing MAVProxy's throttle")
    mp.type("arm throttle")
    gcs.wait(lambda: gcs.last["HEARTBEAT"].base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, gcs.wall(10), "armed")
    mp.out.wait("ARMED", 10)

    mp.type("rc 3 1800")  # throttle up: take off
    gcs.wait(lambda: (m := lpn()) is not None and m.z < -6.0, gcs.wall(30), "6 m up on the throttle")
    mp.type("rc 3 1500")  # mid-stick: hold the altitude
    gcs.wait(lambda: abs(lpn().vz) < 0.3, gcs.wall(15), "the climb stopped at mid-stick")

    start = lpn()
    mp.type("rc 2 1300")  # pitch forward
    yaw = gcs.last["ATTITUDE"].yaw

    def travelled() -> tuple[float, float]:
        m = lpn()
        return ((m.x - start.x) * math.cos(yaw) + (m.y - start.y) * math.sin(yaw),
                -(m.x - start.x) * math.sin(yaw) + (m.y - start.y) * math.cos(yaw))

    gcs.wait(lambda: math.hypot(lpn().vx, lpn().vy) > 2.0 and travelled()[0] > 5.0, gcs.wall(20),
             "5 m forward at more than 2 m/s")
    along, across = travelled()
    assert abs(across) < 0.3 * along, (along, across)

    mp.type("rc 2 1500")  # centred: brake and hold
    gcs.wait(lambda: math.hypot(lpn().vx, lpn().vy) < 0.3, gcs.wall(20), "stopped with the sticks centred")
    held = lpn()
    gcs.wait(lambda: lpn().time_boot_ms > held.time_boot_ms + 3000, gcs.wall(5), "3 s of hold")
    assert math.dist((lpn().x, lpn().y), (held.x, held.y)) < 1.5
    assert gcs.modes_seen[-1] == LOITER

    mp.type("rc 3 1000")  # throttle down: descend, land, disarm after DISARM_DELAY
    gcs.wait(lambda: gcs.last["EXTENDED_SYS_STATE"].landed_state == M.MAV_LANDED_STATE_ON_GROUND
             if "EXTENDED_SYS_STATE" in gcs.last else lpn().z > -0.3, gcs.wall(40), "landed")
    gcs.wait(lambda: not gcs.last["HEARTBEAT"].base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, gcs.wall(30),
             "disarmed after DISARM_DELAY")
    mp.out.wait("DISARMED", 10)
    assert gcs.modes_seen[-1] == LOITER  # no failsafe: MAVProxy kept sending its sticks
