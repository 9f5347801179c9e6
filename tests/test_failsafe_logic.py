"""Safety (failsafe) decisions against the kinematic stand-in vehicle and a recording mode switch."""

from __future__ import annotations

import pytest

from autopilot_model.modules.mission import FENCE, MissionItem
from autopilot_model.modules.safety import BRAKE, LAND, RTL
from harness.kinematic import ON_GROUND, fly, geo


def test_gcs_loss_only_after_a_heartbeat_and_when_armed(safety_rig):
    v, ep, modes, _, safety = safety_rig
    v.params.set("FS_GCS_ENABLE", 1)
    fly(v, (0, 0, -10))
    v.run(10, safety.periodic)
    assert modes.calls == []  # no GCS ever seen
    ep.last_gcs_heartbeat_s = v.t
    v.run(4.9, safety.periodic)
    assert modes.calls == []
    v.run(0.3, safety.periodic)
    assert modes.mode == RTL and safety.gcs_failsafe
    assert any(t.startswith("GCS Failsafe") for t in ep.texts)
    v.run(5, safety.periodic)
    assert len(modes.calls) == 1  # acts once
    ep.last_gcs_heartbeat_s = v.t
    v.run(0.2, safety.periodic)
    assert not safety.gcs_failsafe and "GCS Failsafe Cleared" in ep.texts


def test_gcs_loss_disabled_or_disarmed_or_land_option(safety_rig):
    v, ep, modes, _, safety = safety_rig
    fly(v, (0, 0, -10))
    ep.last_gcs_heartbeat_s = 0.0
    v.run(8, safety.periodic)  # FS_GCS_ENABLE = 0 by default
    assert modes.calls == []
    v.params.set("FS_GCS_ENABLE", 5)
    v.nav.armed = False
    v.run(1, safety.periodic)
    assert modes.calls == []
    v.nav.armed = True
    v.run(0.2, safety.periodic)
    assert modes.mode == LAND


def test_battery_low_rtl_then_critical_land(safety_rig):
    v, ep, modes, _, safety = safety_rig
    v.params.set("BATT_LOW_TIMER", 1)
    fly(v, (0, 0, -10))
    v.battery_voltage = 14.2
    v.run(3, safety.periodic)
    assert modes.calls == []
    v.battery_voltage = 13.9  # below 3.5 V/cell of the 4S pack
    v.run(0.5, safety.periodic)
    assert modes.calls == []  # BATT_LOW_TIMER not yet elapsed
    v.run(0.7, safety.periodic)
    assert modes.mode == RTL and safety.battery_level == 1
    assert any("Battery 1 is low" in t for t in ep.texts)
    v.battery_voltage = 13.5
    v.run(1.2, safety.periodic)
    assert modes.mode == LAND and safety.battery_level == 2
    v.battery_voltage = 16.0
    v.run(1, safety.periodic)
    assert len(modes.calls) == 2  # latched


def test_battery_mah_threshold_and_rtl_fallback_to_land(safety_rig):
    v, _, modes, _, safety = safety_rig
    v.params.set("BATT_LOW_MAH", 1000)
    modes.deny = {RTL}
    fly(v, (0, 0, -10))
    v.battery.consumed_mah = v.params.get("BATT_CAPACITY") - 900
    v.run(0.2, safety.periodic)
    assert modes.calls == [RTL, LAND] and modes.mode == LAND


def test_failsafe_on_ground_disarms(safety_rig):
    v, _, modes, _, safety = safety_rig
    v.params.set("BATT_LOW_TIMER", 0)
    v.nav.armed, v.nav.landed_state = True, ON_GROUND
    v.battery_voltage = 13.0
    v.run(0.2, safety.periodic)
    assert not v.nav.armed and modes.calls == []


def test_fence_altitude_and_radius(safety_rig):
    v, ep, modes, _, safety = safety_rig
    v.params.set("FENCE_ENABLE", 1)
    v.params.set("FENCE_ALT_MAX", 30)
    v.params.set("FENCE_RADIUS", 50)
    fly(v, (10, 0, -29))
    v.run(0.5, safety.periodic)
    assert modes.calls == []
    v.state.position_ned = (10, 0, -31)
    v.run(0.2, safety.periodic)
    assert modes.mode == RTL and "Max Alt fence breached" in ep.texts
    v.state.position_ned = (10, 0, -20)
    v.run(0.2, safety.periodic)
    assert "Fence breach cleared" in ep.texts
    v.params.set("FENCE_ACTION", 4)
    modes.mode = 4
    v.state.position_ned = (40, 40, -20)
    v.run(0.2, safety.periodic)
    assert modes.mode == BRAKE and safety.fence_breached == 2
    v.state.position_ned = (45, 45, -20)  # a little further: no new action
    v.run(0.2, safety.periodic)
    assert len(modes.calls) == 2
    v.state.position_ned = (60, 60, -20)  # 20 m beyond the first breach: the backup fence
    v.run(0.2, safety.periodic)
    assert len(modes.calls) == 3


def test_fence_polygon_from_fence_plan(safety_rig):
    v, ep, modes, store, safety = safety_rig
    v.params.set("FENCE_ENABLE", 1)
    corners = [(-20, -20), (20, -20), (20, 20), (-20, 20)]
    store.replace(FENCE, [MissionItem(seq=i, frame=5, command=5001, param1=4, x=geo(n, e)[0], y=geo(n, e)[1],
                                      mission_type=FENCE) for i, (n, e) in enumerate(corners)])
    fly(v, (15, 15, -10))
    v.run(0.3, safety.periodic)
    assert modes.calls == []
    v.state.position_ned = (15, 25, -10)
    v.run(0.2, safety.periodic)
    assert modes.mode == RTL and "Polygon fence breached" in ep.texts
    assert safety.fence_excess()[1] == pytest.approx(5.0, abs=0.05)


def test_fence_off_when_disabled_or_disarmed(safety_rig):
    v, _, modes, _, safety = safety_rig
    fly(v, (0, 0, -200))
    v.run(0.3, safety.periodic)
    v.params.set("FENCE_ENABLE", 1)
    v.nav.armed = False
    v.run(0.3, safety.periodic)
    assert modes.calls == []


def test_no_rtl_while_landing(safety_rig):
    v, ep, modes, _, safety = safety_rig
    v.params.set("FS_GCS_ENABLE", 1)
    modes.mode = LAND
    fly(v, (0, 0, -10))
    ep.last_gcs_heartbeat_s = 0.0
    v.run(6, safety.periodic)
    assert modes.calls == [] and any("continuing LAND" in t for t in ep.texts)


def test_sim_battery_capacity_param(safety_rig):
    v, *_ = safety_rig
    v.params.set("SIM_BATT_CAP_AH", 0.5)
    assert v.battery.capacity_mah == pytest.approx(500.0)

