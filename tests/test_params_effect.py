"""Parameters a ground station sets take effect, at start (persisted) and in flight.

Judged by what the vehicle does, never by the echoed value: the same flight (same seed, so the model is
deterministic) is flown with a parameter at its default, set before take-off, loaded from the saved
file by a restarted vehicle, and set in flight. ArduCopter loads its saved parameters from storage
before any library copies them (``AP_Param::load_all`` early in ``AP_Vehicle::setup``), and its
controllers read the parameter objects themselves, so a PARAM_SET is flown at once.
"""

from __future__ import annotations

import math
import socket
from pathlib import Path

import pytest

from autopilot_model.modules.flight_modes import GUIDED
from autopilot_model.sitl import Sitl
from taskflight_common.ports import free_ports

pytestmark = pytest.mark.integration


def _sitl(state_dir: Path) -> Sitl:
    return Sitl(urls=[f"udpin:127.0.0.1:{free_ports(1, socket.SOCK_DGRAM)[0]}"], state_dir=state_dir)


def _tilt_deg(q: tuple[float, ...]) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (q[1] ** 2 + q[2] ** 2)))))


def _fly(sitl: Sitl, in_flight: tuple[str, float] | None = None) -> tuple[float, float]:
    """Take off to 10 m in GUIDED and fly 60 m north at 10 m/s; optionally set a parameter once at
    altitude (two seconds before the move). Returns (maximum true tilt, RMS attitude error against the
    controller's desired attitude), both in degrees, over the horizontal move."""
    v = sitl.vehicle
    assert v.wait_estimator(10.0)
    assert sitl.modes.set_mode(GUIDED)[0]
    assert v.nav.arm()[0] and v.nav.takeoff(10.0)[0]
    assert v.run_until(lambda: v.world.x[2] < -9.5, 30.0)
    if in_flight is not None:
        v.params.set(*in_flight)
    v.run_for(2.0)  # settle, so the move alone is judged
    assert v.nav.goto((60.0, 0.0, -10.0), speed=10.0)[0]
    max_tilt = 0.0
    sq = 0.0
    n = 0
    end = v.clock.now() + 15.0
    while v.clock.now() < end:
        v.step(5)
        q = v.world.x[6:10]
        o = v.control.out
        max_tilt = max(max_tilt, _tilt_deg(q))
        dot = abs(o[4] * q[0] + o[5] * q[1] + o[6] * q[2] + o[7] * q[3])
        sq += (2.0 * math.acos(min(1.0, dot))) ** 2
        n += 1
    assert math.dist(v.world.position, (60.0, 0.0, -10.0)) < 5.0
    return max_tilt, math.degrees(math.sqrt(sq / n))


def _flight(state_dir: Path, before: tuple[str, float] | None = None,
            in_flight: tuple[str, float] | None = None) -> tuple[float, float]:
    sitl = _sitl(state_dir)
    try:
        if before is not None:
            sitl.vehicle.params.set(*before)
        return _fly(sitl, in_flight)
    finally:
        sitl.close()


def test_persisted_angle_max_bounds_the_tilt_after_a_restart(tmp_path: Path) -> None:
    default_tilt, _ = _flight(tmp_path / "default")
    assert default_tilt > 20.0  # the move is aggressive enough for the limit to matter
    saved = _sitl(tmp_path / "saved")
    saved.vehicle.params.set("ANGLE_MAX", 1000)  # 10 degrees, saved to <state>/instance0/params.json
    saved.close()
    restarted = _sitl(tmp_path / "saved")
    try:
        assert restarted.vehicle.params.get("ANGLE_MAX") == 1000
        tilt, _ = _fly(restarted)
    finally:
        restarted.close()
    assert tilt < 10.0 + 1.0, f"flew {tilt:.1f} deg with ANGLE_MAX 10 deg loaded at start"


def test_persisted_rate_gain_is_flown_after_a_restart(tmp_path: Path) -> None:
    _, default_err = _flight(tmp_path / "default")
    _, set_err = _flight(tmp_path / "set", before=("ATC_RAT_RLL_P", 8.0))
    assert set_err > 1.2 * default_err, (set_err, default_err)  # the gain changes the response
    saved = _sitl(tmp_path / "saved")
    saved.vehicle.params.set("ATC_RAT_RLL_P", 8.0)
    saved.close()
    _, restarted_err = _flight(tmp_path / "saved")
    # the restarted vehicle flies exactly what a vehicle with the gain set before take-off flies
    assert restarted_err == pytest.approx(set_err, rel=1e-9), (restarted_err, set_err, default_err)


@pytest.mark.parametrize(("name", "value"), [("ANGLE_MAX", 1000), ("ATC_RAT_RLL_P", 8.0)])
def test_parameter_set_in_flight_changes_the_flight(tmp_path: Path, name: str, value: float) -> None:
    default = _flight(tmp_path / "default")
    changed = _flight(tmp_path / "changed", in_flight=(name, value))
    if name == "ANGLE_MAX":
        assert changed[0] < value / 100.0 + 1.0 < default[0], (changed, default)
    else:
        assert changed[1] > 1.2 * default[1], (changed, default)


def test_saved_system_id_is_used_from_the_start(tmp_path: Path) -> None:
    """MAV_SYSID is read once at start (ArduPilot: reboot required): a saved one is on the wire after a
    restart."""
    saved = _sitl(tmp_path)
    assert saved.endpoint.mav.srcSystem == 1
    saved.vehicle.params.set("MAV_SYSID", 7)
    saved.close()
    restarted = _sitl(tmp_path)
    try:
        assert restarted.endpoint.sysid == 7 and restarted.endpoint.mav.srcSystem == 7
    finally:
        restarted.close()


def test_store_applies_saved_values_whenever_attached(tmp_path: Path) -> None:
    """The store's rules: a saved value reaches the subscribers when the file is attached late, is
    applied at declaration when attached early, and wins over an airframe default."""
    from autopilot_model.params import ParamStore

    path = tmp_path / "params.json"
    path.write_text('{"A_GAIN": 2.5, "B_GAIN": 4.0, "NOT_DECLARED": 1}', encoding="utf-8")
    late = ParamStore()
    late.define("A_GAIN", 1.0, 0.0, 10.0)
    seen: list[tuple[str, float]] = []
    late.subscribe("A_", lambda n, v: seen.append((n, v)))
    late.attach_file(path)
    assert seen == [("A_GAIN", 2.5)]
    early = ParamStore()
    early.attach_file(path)
    early.define("B_GAIN", 1.0, 0.0, 10.0)
    early.define("C_GAIN", 1.0, 0.0, 10.0)
    assert early.get("B_GAIN") == 4.0
    assert early.set_default("B_GAIN", 3.0) == 4.0  # the airframe's value does not override the saved one
    assert early.set_default("C_GAIN", 3.0) == 3.0
    assert early.unknown_saved() == ["A_GAIN", "NOT_DECLARED"]
    early.set("C_GAIN", 5.0)  # saving keeps what no piece has declared yet
    assert '"NOT_DECLARED": 1' in path.read_text(encoding="utf-8")
