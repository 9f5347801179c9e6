"""Signing and invalid fields against the whole model process.

A SITL with a signing key: an unsigned ground station is not acted on, a signed one is; NaN or
infinite fields in GUIDED targets change nothing and are counted; the vehicle keeps flying.
"""

from __future__ import annotations

import math
import time

import pytest

from autopilot_model.mavlink.signing import key_from_passphrase
from harness.observer import GUIDED, LOITER, POS_ONLY, VEL_ONLY, Gcs, M
from harness.timing import SPEEDUP

pytestmark = pytest.mark.integration

PASSPHRASE = "taskflight-signing-test"


SITL_EXTRA = ("--signing-key", PASSPHRASE)  # the sitl_port fixture: the model signs its link


def test_unsigned_refused_signed_accepted_then_invalid_fields_ignored(sitl_port: int) -> None:
    key = key_from_passphrase(PASSPHRASE)
    gcs = Gcs(sitl_port, key=key)
    gcs.wait(lambda: gcs.last.get("HEARTBEAT"), 20, "heartbeat")
    mode0 = gcs.fresh("HEARTBEAT").custom_mode
    assert mode0 != LOITER
    plain = Gcs(sitl_port, sysid=250)
    plain.conn.mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_MODE, 0, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                     LOITER, 0, 0, 0, 0, 0)
    # two simulated seconds later: no ACK to the unsigned sender, no mode change
    end = time.monotonic() + 2.0 * 3 / SPEEDUP + 0.5
    while time.monotonic() < end:
        plain.pump()
        gcs.pump()
        time.sleep(0.002)
    assert not plain.acks
    assert gcs.fresh("HEARTBEAT").custom_mode == mode0

    assert gcs.command_ack(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED).result == 0
    assert gcs.fresh("HEARTBEAT").custom_mode == GUIDED

    # fly, then send invalid GUIDED targets: nothing may move the vehicle
    gcs.wait_prearm(30)
    assert gcs.command_ack(M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == 0
    assert gcs.command_ack(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5.0).result == 0

    def near(target: tuple[float, float, float], tol: float) -> bool:
        m = gcs.last.get("LOCAL_POSITION_NED")
        return m is not None and math.dist((m.x, m.y, m.z), target) < tol

    # straight up from wherever the (GPS-grade) estimate starts: judge the altitude only
    gcs.wait(lambda: (m := gcs.last.get("LOCAL_POSITION_NED")) is not None and abs(m.z + 5.0) < 0.6, 30,
             "take-off to 5 m")
    before = gcs.fresh("LOCAL_POSITION_NED")
    for mask, vals in ((POS_ONLY, (math.nan, 0.0, -5.0, 0, 0, 0)), (POS_ONLY, (math.inf, 1.0, -5.0, 0, 0, 0)),
                       (VEL_ONLY, (0, 0, 0, math.nan, 2.0, 0.0)), (VEL_ONLY, (0, 0, 0, -math.inf, 0.0, 0.0))):
        gcs.local_target(M.MAV_FRAME_LOCAL_NED, mask, *vals)
    end = time.monotonic() + 2.0 * 3 / SPEEDUP + 0.5
    while time.monotonic() < end:
        gcs.pump()
        time.sleep(0.002)
    after = gcs.fresh("LOCAL_POSITION_NED")
    assert math.dist((before.x, before.y, before.z), (after.x, after.y, after.z)) < 0.5
    assert gcs.fresh("HEARTBEAT").custom_mode == GUIDED
    # a valid target still works afterwards
    gcs.local_target(M.MAV_FRAME_LOCAL_NED, POS_ONLY, 10.0, 0.0, -5.0)
    gcs.wait(lambda: near((10.0, 0.0, -5.0), 0.6), 40, "valid target after invalid ones")
