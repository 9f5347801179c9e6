"""Failsafes over loopback UDP: GCS heartbeat loss, battery low/critical, geofence altitude and radius.

One SITL subprocess for the module (lockstep, paced at SPEEDUP); pymavlink is the ground station. Each
test flies from the ground, triggers its failsafe, checks the announced STATUSTEXT and the resulting
mode in the HEARTBEAT, and leaves the vehicle landed and disarmed with the failsafe switched off again.
"""

from __future__ import annotations

import math

import pytest

from harness.observer import BRAKE, GUIDED, LAND, POS_ONLY, RTL, Gcs, M
from harness.timing import wall

pytestmark = pytest.mark.integration


# the gcs fixture's ground station: heartbeats at 2 Hz of simulated time, a margin for the GCS failsafe
# (FS_GCS_ENABLE) when a wait lags
GCS_OPTIONS = {"heartbeat_hz": 2.0}


def text_seen(gcs: Gcs, fragment: str) -> bool:
    return any(fragment in t for t in gcs.texts)


def goto(gcs: Gcs, n: float, e: float, alt: float) -> None:
    gcs.local_target(M.MAV_FRAME_LOCAL_NED, POS_ONLY, n, e, -alt)


def test_gcs_heartbeat_loss_rtl(gcs: Gcs) -> None:
    gcs.set_param("FS_GCS_ENABLE", 1)
    gcs.takeoff(8)
    gcs.texts.clear()
    gcs.heartbeats.clear()  # the ground station goes silent but keeps listening
    try:
        gcs.wait_mode(RTL, 5 + 5)
        assert text_seen(gcs, "GCS Failsafe")
    finally:
        gcs.heartbeats.set()
    gcs.wait(lambda: text_seen(gcs, "GCS Failsafe Cleared"), wall(3), "failsafe cleared")
    gcs.wait_disarmed(60)  # RTL lands at home
    n, e, _ = gcs.positions[-1]
    assert math.hypot(n, e) < 2.0
    gcs.set_param("FS_GCS_ENABLE", 0)


def test_fence_altitude_rtl_and_radius_brake(gcs: Gcs) -> None:
    """As ArduCopter: a GUIDED target beyond the fence is ignored; the fence moved in under the vehicle is
    a breach (announced "Max Alt fence breached"), answered by FENCE_ACTION."""
    gcs.set_param("FENCE_ALT_MAX", 20)
    gcs.set_param("FENCE_RADIUS", 100)
    gcs.set_param("FENCE_ACTION", 1)  # RTL
    gcs.set_param("FENCE_ENABLE", 1)
    gcs.takeoff(10)
    gcs.texts.clear()
    goto(gcs, 0, 0, 28)  # above FENCE_ALT_MAX: refused, the vehicle keeps holding 10 m
    t0 = gcs.last["LOCAL_POSITION_NED"].time_boot_ms
    gcs.wait(lambda: gcs.last["LOCAL_POSITION_NED"].time_boot_ms > t0 + 3000, wall(5), "3 s")
    assert max(-p[2] for p in gcs.positions[-10:]) < 11.0
    goto(gcs, 0, 0, 18)
    gcs.wait_alt(18, 20)
    gcs.set_param("FENCE_ALT_MAX", 15)
    gcs.wait_mode(RTL, 20)
    assert text_seen(gcs, "Max Alt fence breached")
    gcs.wait(lambda: text_seen(gcs, "Fence breach cleared"), wall(60), "breach cleared")
    gcs.wait_disarmed(90)

    gcs.set_param("FENCE_ALT_MAX", 20)
    gcs.set_param("FENCE_ACTION", 4)  # BRAKE
    gcs.takeoff(10)
    gcs.texts.clear()
    goto(gcs, 60, 0, 10)
    gcs.wait(lambda: gcs.last["LOCAL_POSITION_NED"].x > 30.5, wall(30), "30 m out")
    gcs.set_param("FENCE_RADIUS", 30)
    gcs.wait_mode(BRAKE, 30)
    assert text_seen(gcs, "Circle fence breached")
    stopped = gcs.wait(lambda: (m := gcs.last.get("LOCAL_POSITION_NED")) is not None
                       and math.hypot(m.vx, m.vy) < 0.2 and m, wall(10), "stopped by BRAKE")
    assert 30 <= stopped.x < 42, stopped  # stopped just beyond the 30 m fence, not at the 60 m target
    assert gcs.heartbeat().custom_mode == BRAKE
    gcs.set_param("FENCE_ENABLE", 0)
    gcs.land_and_disarm()


def test_battery_low_rtl_then_critical_land(gcs: Gcs) -> None:
    gcs.set_param("BATT_LOW_TIMER", 1)
    gcs.set_param("BATT_CRT_VOLT", 0)  # critical off for the first part
    gcs.takeoff(10)
    used = gcs.fresh("BATTERY_STATUS").current_consumed
    assert used > 0
    gcs.texts.clear()
    # a small pack: what has been used so far is 88 % of it, so the voltage sags below BATT_LOW_VOLT
    gcs.set_param("SIM_BATT_CAP_AH", round(used / 0.88 / 1000.0, 4))
    gcs.wait_mode(RTL, 10)
    assert text_seen(gcs, "Battery 1 is low")
    volts = gcs.fresh("BATTERY_STATUS").voltages[0] / 1000.0
    gcs.set_param("BATT_CRT_VOLT", round(volts + 0.5, 2))
    gcs.wait_mode(LAND, 10)
    assert text_seen(gcs, "Battery 1 is critical")
    gcs.wait_disarmed(90)
    gcs.set_param("SIM_BATT_CAP_AH", 5.0)  # a fresh pack for whatever runs next
    assert GUIDED in gcs.modes_seen
