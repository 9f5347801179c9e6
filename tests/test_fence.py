"""The geofence's decisions (ArduPilot's AC_Fence as ArduCopter runs it) on the kinematic stand-in vehicle.

Each test checks one rule against the source it comes from: AC_Fence::check (floor auto-enable, the
backup fence, breach counts), pre_arm_check's texts, check_destination_within_fence, DO_FENCE_ENABLE's
types, and Copter::fence_check's actions (LAND beyond 100 m). The breach seen by a ground station, on
both autopilots, is in ``tests/test_differential_fence.py``.
"""

from __future__ import annotations

from autopilot_model.modules import fence as fm
from autopilot_model.modules.safety import LAND, RTL
from harness.kinematic import ON_GROUND, fly


def test_enable_param_enables_all_but_the_floor_and_do_fence_enable_is_not_persisted(fence_rig):
    v, _, _, _, fence = fence_rig
    v.params.set("FENCE_TYPE", 15)
    assert not fence.enabled
    v.params.set("FENCE_ENABLE", 1)
    assert fence.enabled_fences == fm.ALT_MAX | fm.CIRCLE | fm.POLYGON  # the floor waits for its height
    assert fence.enable(False) == fm.ALT_MAX | fm.CIRCLE | fm.POLYGON
    assert not fence.enabled and v.params.get("FENCE_ENABLE") == 1  # DO_FENCE_ENABLE 0 changes no parameter
    v.params.set("FENCE_TYPE", 7)
    assert fence.enable(True, fm.ALT_MIN) == 0  # not configured: nothing changes (the command is FAILED)


def test_floor_enables_itself_above_min_alt_plus_margin_and_breaches_below(fence_rig):
    v, ep, modes, safety, fence = fence_rig
    v.params.set("FENCE_TYPE", 15)
    v.params.set("FENCE_ALT_MIN", 5)
    v.params.set("FENCE_MARGIN", 3)
    v.params.set("FENCE_ENABLE", 1)
    fly(v, (0, 0, -7.5))  # below ALT_MIN + MARGIN: the floor stays off
    v.run(0.3, safety.periodic)
    assert not fence.enabled_fences & fm.ALT_MIN
    v.state.position_ned = (0, 0, -8.5)
    v.run(0.2, safety.periodic)
    assert fence.enabled_fences & fm.ALT_MIN and "Min Alt fence enabled (auto enable)" in ep.texts
    v.state.position_ned = (0, 0, -4.0)
    v.run(0.2, safety.periodic)
    assert "Min Alt fence breached" in ep.texts and modes.mode == RTL
    assert fence.breach_count == 1 and fence.breached == fm.ALT_MIN


def test_floor_is_dropped_while_landing_so_landing_is_no_breach(fence_rig):
    v, _ep, modes, safety, fence = fence_rig
    v.params.set("FENCE_TYPE", 15)
    v.params.set("FENCE_ALT_MIN", 5)
    v.params.set("FENCE_ENABLE", 1)
    fly(v, (0, 0, -10))
    v.run(0.2, safety.periodic)
    assert fence.enabled_fences & fm.ALT_MIN
    v.nav.landed_state = 4  # LANDING
    v.state.position_ned = (0, 0, -1)
    v.run(0.2, safety.periodic)
    assert not fence.breached and modes.calls == [] and not fence.enabled_fences & fm.ALT_MIN


def test_prearm_texts(fence_rig):
    v, _, _, _safety, fence = fence_rig
    assert fence.prearm_failure() is None  # not enabled: no checks
    fence.enable(True)
    v.params.set("FENCE_ALT_MAX", 20)
    v.params.set("FENCE_ALT_MIN", 50)
    assert fence.prearm_failure() == "FENCE_ALT_MAX < FENCE_ALT_MIN"
    v.params.set("FENCE_ALT_MAX", 100)
    v.params.set("FENCE_ALT_MIN", 97)
    assert fence.prearm_failure() == "FENCE_MARGIN too big"  # 100 - 97 <= 2 * FENCE_MARGIN
    v.params.set("FENCE_MARGIN", 1)
    assert fence.prearm_failure() is None
    v.params.set("FENCE_TYPE", 0)
    v.params.set("FENCE_ENABLE", 1)
    assert fence.prearm_failure() == "Fences enabled, but none selected"


def test_breach_while_disarmed_fails_the_prearm_check(fence_rig):
    v, _, modes, safety, fence = fence_rig
    fence.enable(True)
    v.state.position_ned = (400, 0, 0)  # beyond FENCE_RADIUS 300, on the ground, disarmed
    v.run(0.2, safety.periodic)
    assert fence.prearm_failure() == "Vehicle breaching Circle fence" and modes.calls == []


def test_destination_check(fence_rig):
    v, _, _, _, fence = fence_rig
    assert fence.destination_ok((1000, 0, -500))  # no fence enabled
    v.params.set("FENCE_TYPE", 15)
    v.params.set("FENCE_ALT_MIN", 3)
    fence.enable(True)
    assert fence.destination_ok((250, 0, -50))
    assert not fence.destination_ok((301, 0, -50))
    assert not fence.destination_ok((0, 0, -101))
    assert not fence.destination_ok((0, 0, -2))  # below the floor, enabled by hand


def test_backup_fence_and_give_up_distance(fence_rig):
    v, ep, modes, safety, fence = fence_rig
    v.params.set("FENCE_RADIUS", 50)
    v.params.set("FENCE_ENABLE", 1)
    fly(v, (55, 0, -10))
    v.run(0.2, safety.periodic)
    assert modes.calls == [RTL] and "Circle fence breached" in ep.texts
    v.state.position_ned = (70, 0, -10)  # not yet 20 m beyond the first breach
    v.run(0.2, safety.periodic)
    assert modes.calls == [RTL]
    v.state.position_ned = (76, 0, -10)  # 20 m further: the backup fence acts again
    v.run(0.2, safety.periodic)
    assert modes.calls == [RTL, RTL] and fence.breach_count == 2
    v.state.position_ned = (200, 0, -10)  # more than 100 m outside: ArduCopter lands
    v.run(0.2, safety.periodic)
    assert modes.calls[-1] == LAND


def test_breach_on_the_ground_disarms(fence_rig):
    v, _, modes, safety, _fence = fence_rig
    v.params.set("FENCE_ENABLE", 1)
    v.nav.armed, v.nav.landed_state = True, ON_GROUND
    v.state.position_ned = (400, 0, 0)
    v.run(0.2, safety.periodic)
    assert not v.nav.armed and modes.calls == []


def test_report_only_changes_no_mode(fence_rig):
    v, ep, modes, safety, _ = fence_rig
    v.params.set("FENCE_ACTION", 0)
    v.params.set("FENCE_ENABLE", 1)
    fly(v, (0, 0, -120))
    v.run(0.2, safety.periodic)
    assert modes.calls == [] and "Max Alt fence breached" in ep.texts
