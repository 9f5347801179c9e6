"""Belief updaters (seed 001 Sec. 6.2.5): the common updater fed by a real VehicleMirror, the runner."""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.behaviors.beliefs import Belief, BeliefMemory
from companion.behaviors.updaters import (
    BeliefUpdater,
    BeliefUpdaterRunner,
    CommonBeliefUpdater,
    charge_level,
)
from companion.link.mirror import GUIDED, LAND, MirrorState, VehicleMirror
from companion.node import FlightState, VehicleStatus, flight_state

M = mavlink  # the ArduPilot dialect, as the link uses it

ARMED = M.MAV_MODE_FLAG_SAFETY_ARMED | M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
DISARMED = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


class Vehicle:
    """A VehicleMirror fed with real MAVLink messages, packed and decoded as the link would."""

    def __init__(self) -> None:
        self.mirror = VehicleMirror()
        self._tx = M.MAVLink(None, srcSystem=1, srcComponent=1)
        self._rx = M.MAVLink(None)

    def feed(self, msg: Any) -> None:
        decoded = self._rx.decode(bytearray(msg.pack(self._tx)))
        assert self.mirror.update(decoded, time.monotonic())

    def heartbeat(self, armed: bool, mode: int) -> None:
        self.feed(M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                              ARMED if armed else DISARMED, mode, M.MAV_STATE_ACTIVE, 3))

    def position(self, t_ms: int, n: float, e: float, d: float) -> None:
        self.feed(M.MAVLink_local_position_ned_message(t_ms, n, e, d, 0.0, 0.0, 0.0))

    def landed_state(self, state: int) -> None:
        self.feed(M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_MC, state))

    def battery(self, remaining: int) -> None:
        self.feed(M.MAVLink_sys_status_message(0, 0, 0, 500, 12600, -1, remaining, 0, 0, 0, 0, 0, 0))

    def home(self, lat: float, lon: float, alt: float) -> None:
        self.feed(M.MAVLink_home_position_message(int(lat * 1e7), int(lon * 1e7), int(alt * 1000),
                                                  0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0))


def _updater(v: Vehicle, **kw: Any) -> CommonBeliefUpdater:
    return CommonBeliefUpdater(lambda: VehicleStatus.of(v.mirror.snapshot()), **kw)


def test_position_time_is_mirrored() -> None:
    v = Vehicle()
    assert v.mirror.snapshot().position_time_ms is None
    v.position(12345, 1.0, 2.0, -3.0)
    s = v.mirror.snapshot()
    assert s.position_time_ms == 12345 and s.time_boot_ms == 12345
    v.feed(M.MAVLink_attitude_message(13000, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0))
    s = v.mirror.snapshot()
    assert s.position_time_ms == 12345 and s.time_boot_ms == 13000  # only LOCAL_POSITION_NED sets it


def test_common_beliefs_from_a_flying_vehicle() -> None:
    v = Vehicle()
    v.heartbeat(armed=True, mode=GUIDED)
    v.landed_state(M.MAV_LANDED_STATE_IN_AIR)
    v.position(20_000, 10.004, -4.256, -5.0)
    v.battery(87)
    v.home(47.3977419, 8.5455938, 488.0)
    m = BeliefMemory()
    _updater(v).update(m, 20.3)
    expected = {
        "object(self, aerial_robot)", "object(1, battery)", "flight_state(self, flying)", "armed(self, yes)",
        "position(self, (10.0, -4.26, 5.0))", "localization(self, healthy)", "mode(self, GUIDED)",
        "charge(1, high)", "battery_percentage(1, 87)", "home(self, (47.3977419, 8.5455938, 488.0))",
    }
    assert {str(b) for b in m.beliefs()} == expected
    assert m.consult("object(?x, battery), charge(?x, ?y)") == [{"x": 1, "y": "high"}]


def test_beliefs_follow_the_vehicle() -> None:
    v = Vehicle()
    m = BeliefMemory()
    u = _updater(v)
    # nothing known yet: landed, disarmed, no position, unhealthy, no mode / charge / home
    u.update(m, 0.0)
    assert m.value("flight_state", "self") == "landed"
    assert m.value("localization", "self") == "unhealthy"
    assert m.value("position", "self") is None and m.value("mode", "self") is None
    assert m.value("charge", 1) is None and m.holds("object(1, battery)")

    v.heartbeat(armed=False, mode=GUIDED)
    v.landed_state(M.MAV_LANDED_STATE_ON_GROUND)
    v.position(1_000, 0.0, 0.0, -0.001)
    v.battery(100)
    u.update(m, 1.2)
    assert m.value("flight_state", "self") == "landed"
    assert m.value("position", "self") == (0.0, 0.0, 0.0)
    assert str(m.beliefs("position")[0]) == "position(self, (0.0, 0.0, 0.0))"  # no -0.0
    assert m.value("charge", 1) == "full" and m.value("armed", "self") == "no"

    v.heartbeat(armed=True, mode=GUIDED)
    v.landed_state(M.MAV_LANDED_STATE_TAKEOFF)
    v.position(2_000, 0.0, 0.0, -0.5)
    u.update(m, 2.0)
    assert m.value("flight_state", "self") == "taking_off" and m.value("armed", "self") == "yes"

    v.landed_state(M.MAV_LANDED_STATE_IN_AIR)
    v.battery(25)
    u.update(m, 2.5)
    assert m.value("flight_state", "self") == "flying"
    assert m.value("charge", 1) == "low" and m.value("battery_percentage", 1) == 25
    assert len(m.beliefs("charge")) == 1  # the old level was retracted

    v.heartbeat(armed=True, mode=LAND)  # LAND mode while still reported in the air
    u.update(m, 3.0)
    assert m.value("flight_state", "self") == "landing" and m.value("mode", "self") == "LAND"

    v.landed_state(M.MAV_LANDED_STATE_LANDING)
    v.heartbeat(armed=True, mode=GUIDED)
    u.update(m, 3.5)
    assert m.value("flight_state", "self") == "landing"

    v.heartbeat(armed=False, mode=LAND)
    v.battery(-1)  # unknown: the charge belief goes
    u.update(m, 4.0)
    assert m.value("flight_state", "self") == "landed"
    assert m.value("charge", 1) is None and m.value("battery_percentage", 1) is None


def test_localization_goes_unhealthy_when_the_estimate_is_stale() -> None:
    v = Vehicle()
    m = BeliefMemory()
    u = _updater(v, max_position_age_s=1.0)
    v.position(10_000, 1.0, 2.0, -3.0)
    u.update(m, 10.9)
    assert m.holds("localization(self, healthy)")
    u.update(m, 11.2)
    assert m.holds("localization(self, unhealthy)")
    assert m.value("position", "self") == (1.0, 2.0, 3.0)  # kept, but flagged by localization
    v.position(11_150, 1.5, 2.0, -3.0)
    u.update(m, 11.2)
    assert m.holds("localization(self, healthy), position(self, (1.5, 2.0, 3.0))")


def test_update_without_a_time_uses_the_clock() -> None:
    v = Vehicle()
    v.position(5_000, 0.0, 0.0, 0.0)
    m = BeliefMemory()
    CommonBeliefUpdater(lambda: VehicleStatus.of(v.mirror.snapshot()), lambda: 5.5).update(m)
    assert m.holds("localization(self, healthy)")
    CommonBeliefUpdater(lambda: VehicleStatus.of(v.mirror.snapshot()), lambda: 9.0).update(m)
    assert m.holds("localization(self, unhealthy)")


def test_flight_state_without_extended_sys_state() -> None:
    on_ground = MirrorState(armed=True, mode=GUIDED, position=(0.0, 0.0, -0.05))
    assert flight_state(on_ground) == "landed"
    up = MirrorState(armed=True, mode=GUIDED, position=(0.0, 0.0, -3.0))
    assert flight_state(up) == "flying"
    assert flight_state(MirrorState(armed=True, mode=LAND, position=(0.0, 0.0, -3.0))) == "landing"
    assert flight_state(MirrorState(armed=False, mode=GUIDED, position=(0.0, 0.0, -3.0))) == "landed"


@pytest.mark.parametrize("percent, level", [
    (100, "full"), (90, "full"), (89, "high"), (60, "high"), (59, "medium"), (30, "medium"),
    (29, "low"), (10, "low"), (9, "empty"), (0, "empty"), (-1, None), (None, None),
])
def test_charge_levels(percent: int | None, level: str | None) -> None:
    assert charge_level(percent) == level


def test_version_is_stable_when_nothing_changes() -> None:
    v = Vehicle()
    v.heartbeat(armed=False, mode=GUIDED)
    v.position(1_000, 1.0, 1.0, 0.0)
    v.battery(50)
    m = BeliefMemory()
    u = _updater(v)
    u.update(m, 1.0)
    ver = m.version
    u.update(m, 1.1)
    assert m.version == ver


# --- the runner ---------------------------------------------------------------------------------------------


class Recorder(BeliefUpdater):
    def __init__(self, name: str, period_s: float) -> None:
        self.name, self.period_s = name, period_s
        self.times: list[float] = []

    def update(self, memory: BeliefMemory, now_s: float) -> None:
        self.times.append(now_s)
        memory.add(Belief("ticks", (self.name, len(self.times))))


class Broken(BeliefUpdater):
    name, period_s = "broken", 0.1

    def __init__(self) -> None:
        self.calls = 0

    def update(self, memory: BeliefMemory, now_s: float) -> None:
        self.calls += 1
        raise RuntimeError("sensor gone")


def test_run_once_respects_each_period() -> None:
    fast, slow = Recorder("fast", 0.5), Recorder("slow", 2.0)
    r = BeliefUpdaterRunner(BeliefMemory(), [fast, slow], now=lambda: 0.0)
    t = 0.0
    while t <= 4.0 + 1e-9:
        r.run_once(round(t, 3))
        t += 0.1
    assert fast.times == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0]
    assert slow.times == [0.0, 2.0, 4.0]
    assert r.stats["fast"].runs == 9


def test_run_once_reschedules_after_a_clock_reset() -> None:
    rec = Recorder("r", 1.0)
    r = BeliefUpdaterRunner(BeliefMemory(), [rec], now=lambda: 0.0)
    assert r.run_once(100.0) == ["r"]
    assert r.run_once(100.5) == []
    assert r.run_once(3.0) == ["r"]  # the autopilot rebooted: do not wait until 101 s
    assert r.run_once(3.5) == [] and r.run_once(4.0) == ["r"]


def test_a_failing_updater_does_not_stop_the_others(caplog: pytest.LogCaptureFixture) -> None:
    broken, ok = Broken(), Recorder("ok", 0.1)
    r = BeliefUpdaterRunner(BeliefMemory(), [broken, ok], now=lambda: 0.0)
    with caplog.at_level("ERROR"):
        assert r.run_once(0.0) == ["broken", "ok"]
        r.run_once(0.1)
    assert broken.calls == 2 and len(ok.times) == 2
    assert r.stats["broken"].errors == 2 and "sensor gone" in (r.stats["broken"].last_error or "")
    assert "belief updater broken failed" in caplog.text


def test_runner_rejects_bad_updaters() -> None:
    with pytest.raises(ValueError, match="unique"):
        BeliefUpdaterRunner(BeliefMemory(), [Recorder("a", 1.0), Recorder("a", 2.0)], now=lambda: 0.0)
    with pytest.raises(ValueError, match="positive"):
        BeliefUpdaterRunner(BeliefMemory(), [Recorder("a", 0.0)], now=lambda: 0.0)


class FastClock:
    """An autopilot clock running ``rate`` times faster than the wall (a sped-up model)."""

    def __init__(self, rate: float) -> None:
        self.rate = rate
        self.t0 = time.monotonic()
        self.lock = threading.Lock()
        self.wall_until_calls = 0

    def now(self) -> float:
        return (time.monotonic() - self.t0) * self.rate

    def wall_until(self, t: float) -> float:
        with self.lock:
            self.wall_until_calls += 1
        return max(0.0, (t - self.now()) / self.rate)


def _wait_for(cond: Any, deadline_s: float) -> bool:
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.01)
    return bool(cond())


def test_thread_runs_updaters_on_a_sped_up_clock() -> None:
    clock = FastClock(rate=10.0)
    rec, broken = Recorder("rec", 1.0), Broken()
    m = BeliefMemory()
    runner = BeliefUpdaterRunner(m, [rec, broken], now=clock.now, wall_until=clock.wall_until)
    with runner:
        # 8 periods of 1 s autopilot time take 0.8 s of wall at 10x: well inside the deadline
        assert _wait_for(lambda: len(rec.times) >= 8, deadline_s=5.0), rec.times
    n = len(rec.times)
    gaps = [b - a for a, b in zip(rec.times, rec.times[1:], strict=False)]
    # paced on the autopilot's clock (a wall-paced runner would leave 10 s gaps), a late call
    # followed by one on schedule
    assert all(0.5 <= g <= 2.0 for g in gaps), gaps
    assert abs((rec.times[-1] - rec.times[0]) / len(gaps) - 1.0) < 0.2, rec.times
    assert broken.calls >= 5  # kept being called although it always raises
    assert clock.wall_until_calls > 0
    assert m.holds(f"ticks(rec, {n})")
    assert not any(t.name == "belief-updaters" for t in threading.enumerate())  # closed and joined
    assert len(rec.times) == n


def test_vehicle_status_is_a_typed_snapshot_of_the_mirror() -> None:
    v = Vehicle()
    v.heartbeat(armed=True, mode=GUIDED)
    v.position(2_000, 1.0, 2.0, -3.0)
    v.landed_state(M.MAV_LANDED_STATE_IN_AIR)
    s = VehicleStatus.of(v.mirror.snapshot(), time_s=2.5)
    assert s.armed and s.mode == "GUIDED" and s.flight is FlightState.FLYING and not s.on_ground
    assert s.position == (1.0, 2.0, -3.0) and s.state is not None and s.time_s == 2.5
    assert not s.overridden
    v.heartbeat(armed=False, mode=GUIDED)
    s = VehicleStatus.of(v.mirror.snapshot())
    assert s.on_ground and s.flight is FlightState.LANDED
