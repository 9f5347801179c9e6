"""The safety monitor's thresholds file and its decisions on a made-up vehicle status (no flight).

The flights are in test_safety_monitor.py (a battery that cannot bring the vehicle home) and
test_rtl_companion.py; here the YAML form refuses bad input naming the field, and the decision ladder
(report once, RTL, then LAND; the layers above told first; emergency as the requester) is checked on a
status the test writes.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from companion.flight import Envelope, Limits
from companion.node import FlightState, VehicleStatus
from companion.safety import Action, SafetyConfig, SafetyDecision, SafetyMonitor, load_safety_config
from taskflight_common.yamlio import ConfigError


def test_the_yaml_form_sets_thresholds_and_refuses_bad_input(tmp_path: Path) -> None:
    good = tmp_path / "safety.yaml"
    good.write_text("battery_margin: 2\nbattery_action: land\nfence: false\nbattery_capacity_mah: null\n")
    c = load_safety_config(good)
    assert (c.battery_margin, c.battery_action, c.fence) == (2.0, Action.LAND, False)
    assert c.battery_capacity_mah is None
    for text, fragment in (("battery_margn: 2\n", "battery_margn: unknown field"),
                           ("\nbattery_margin: -1\n", ":2: battery_margin: must be > 0"),
                           ("estimate_action: panic\n", "estimate_action: must be one of report, rtl, land"),
                           ("link: 3\n", "link: expected true or false")):
        bad = tmp_path / "bad.yaml"
        bad.write_text(text)
        with pytest.raises(ConfigError, match=fragment):
            load_safety_config(bad)


def status(**kw: Any) -> VehicleStatus:
    base = VehicleStatus(time_s=0.0, armed=True, mode="GUIDED", flight=FlightState.FLYING, on_ground=False,
                         overridden=False, position=(30.0, 40.0, -10.0), position_time_ms=0,
                         velocity=(0.0, 0.0, 0.0),
                         yaw=0.0, global_position=None, home=None, battery_remaining=50, state=None,
                         battery_current=36.0, battery_consumed_mah=1000.0, estimate_healthy=True)
    return dataclasses.replace(base, **kw)


class Rig:
    """A monitor over a stub node and coordinator that record what it asks for."""

    def __init__(self, **config: Any) -> None:
        self.now = status()
        self.asked: list[tuple[str, str]] = []
        self.refuse: set[str] = set()
        self.told: list[SafetyDecision] = []
        self.order: list[str] = []
        coordinator = SimpleNamespace(activate=self._activate, ended=[])
        layer = SimpleNamespace(coordinator=coordinator, log=lambda record: None, cycle_listeners=[])
        node = SimpleNamespace(queue=SimpleNamespace(limits=Limits(horizontal_speed=5.0),
                                                     envelope=Envelope.box(-100, 100, -100, 100)))
        self.monitor = SafetyMonitor(node, layer, SafetyConfig(**config), status_of=lambda: self.now)  # type: ignore[arg-type]
        self.monitor.listeners.append(self._tell)

    def _activate(self, request: dict[str, Any], requester: str) -> Any:
        self.asked.append((request["behavior"], requester))
        self.order.append("activate")
        ok = request["behavior"] not in self.refuse
        return SimpleNamespace(accepted=ok, reason="accepted" if ok else "situation: no", activation_id="a1")

    def _tell(self, d: SafetyDecision) -> None:
        self.told.append(d)
        self.order.append("told")


def test_battery_ladder_rtl_then_land_as_emergency_after_telling_the_layers_above() -> None:
    r = Rig()
    # the return: 50 m at 5 m/s + 10 m at 1 m/s = 20 s at 36 A = 200 mAh; 1000 mAh left (50 % of 2000)
    assert r.monitor.check(1.0) is None
    r.now = status(battery_remaining=14, battery_consumed_mah=1720.0)  # 280 mAh left: under 1.5 x 200
    d = r.monitor.check(2.0)
    assert d is not None and (d.check, d.behavior, d.accepted) == ("battery", "RTL", True), d
    assert r.asked == [("RTL", "emergency")] and r.order == ["told", "activate"]
    assert r.monitor.check(3.0) is None  # acted once: nothing more while nothing gets worse
    r.now = status(battery_remaining=9, battery_consumed_mah=1820.0)  # 180 mAh: cannot cover the return
    d = r.monitor.check(4.0)
    assert d is not None and d.behavior == "LAND" and "cannot bring the vehicle home" in d.reason, d
    assert r.asked[-1] == ("LAND", "emergency")
    assert r.monitor.status()["last_decision"]["behavior"] == "LAND"
    r.now = status(armed=False, flight=FlightState.LANDED)  # on the ground: a new flight starts afresh
    assert r.monitor.check(5.0) is None and r.monitor._acted == -1


def test_rtl_refused_falls_back_to_land_and_reports_are_made_once() -> None:
    r = Rig()
    r.refuse = {"RTL"}
    r.now = status(overridden=True, mode="RTL")
    d = r.monitor.check(1.0)
    assert d is not None and d.check == "autopilot_failsafe" and d.behavior is None and r.asked == [], d
    assert r.monitor.check(2.0) is None  # reported once
    r.now = status(velocity=(20.0, 0.0, 0.0), position=(90.0, 0.0, -10.0))  # cannot stop before the fence
    d = r.monitor.check(3.0)
    assert d is not None and d.check == "fence" and d.behavior == "LAND" and d.accepted, d
    assert r.asked == [("RTL", "emergency"), ("LAND", "emergency")]
    assert [x.check for x in r.told] == ["autopilot_failsafe", "fence"]


def test_off_means_not_attached() -> None:
    r = Rig(enabled=False)
    r.monitor.attach()
    assert r.monitor._attached is False and r.monitor.status()["enabled"] is False


def test_the_builder_wires_the_monitor_to_the_mission_and_the_team() -> None:
    from companion.builder import CompanionConfig, build_companion

    companion = build_companion(CompanionConfig("udpout:127.0.0.1:9", control_port=None))
    assert companion.safety is not None and companion._on_safety in companion.safety.listeners
    taken: list[str] = []
    companion.member = SimpleNamespace(safety_stop=taken.append)  # type: ignore[assignment]
    act = SafetyDecision(1.0, "battery", "land", "the battery cannot bring the vehicle home", None, None,
                         "acting")
    companion._on_safety(act)
    assert taken == ["battery: the battery cannot bring the vehicle home"]  # the team task given back
    assert companion.missions is not None
    aborted: list[str] = []
    companion.missions.safety_stop = aborted.append  # type: ignore[method-assign]
    companion._on_safety(dataclasses.replace(act, check="link", action="report"))
    assert len(taken) == 1  # a report leaves the team member to its own tiers
    assert aborted == []  # and the mission flying (the autopilot's own failsafes act)
    direct = build_companion(CompanionConfig("udpout:127.0.0.1:9", control_port=None, behaviors=False))
    assert direct.safety is None
