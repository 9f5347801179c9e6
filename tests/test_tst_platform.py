"""The delegation view of a vehicle (seed 000 Sec. III-A): ``companion.tst.platform.Platform``, its YAML."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from companion.tst.platform import bundled_platform, load_platform, platform_from_dict
from companion.tst.registry import leaf_type_names
from taskflight_common.yamlio import ConfigError, load_yaml_text

HOME = [-35.363261, 149.165230]


def from_yaml(text: str):
    return platform_from_dict(load_yaml_text(text, "p.yaml"), "p.yaml")


def test_bundled_indoor_platform_is_the_small_arena_with_2_m_take_off() -> None:
    p = bundled_platform("indoor")
    assert p.name == "indoor" and p.profile == "indoor" and p.sensor_profile == "indoor"
    assert p.takeoff_altitude == 2.0
    assert p.home == pytest.approx(tuple(HOME))
    assert p.ceiling == (10.0, "FENCE_ALT_MAX")
    assert p.envelope.contains_ne((19.0, -19.0)) and not p.envelope.contains_ne((21.0, 0.0))
    assert set(p.sensors) == {"camera"} and not p.range_sensor
    assert set(p.tasks) == set(leaf_type_names())
    assert p.endurance_s == pytest.approx(600 - 60)


def test_bundled_outdoor_platform_is_bigger_with_5_m_take_off_and_a_range_sensor() -> None:
    indoor, outdoor = bundled_platform("indoor"), bundled_platform("outdoor")
    assert outdoor.takeoff_altitude == 5.0
    assert outdoor.ceiling[0] > indoor.ceiling[0]
    assert outdoor.envelope.contains_ne((150.0, 150.0)) and not indoor.envelope.contains_ne((150.0, 150.0))
    assert outdoor.range_sensor and "laser" in outdoor.sensors
    with pytest.raises(ValueError, match="profile"):
        bundled_platform("underwater")


def test_profile_picks_the_take_off_altitude_unless_given() -> None:
    base = "platform: x\nhome: [-35.36, 149.16]\n"
    assert from_yaml(base + "profile: indoor\n").takeoff_altitude == 2.0
    assert from_yaml(base + "profile: outdoor\n").takeoff_altitude == 5.0
    assert from_yaml(base + "profile: indoor\ntakeoff_altitude: 1.2\n").takeoff_altitude == 1.2


def test_battery_endurance_is_capacity_times_fraction_minus_reserve() -> None:
    p = from_yaml("platform: x\nhome: [0, 0]\nbattery: {capacity_s: 1000, percent: 80, reserve_s: 100}\n")
    assert p.endurance_s == pytest.approx(700.0)
    assert p.with_battery(50).endurance_s == pytest.approx(400.0)
    assert p.with_battery(5).endurance_s == 0.0  # never negative
    assert p.endurance_s == pytest.approx(700.0)  # the original is unchanged (frozen)
    with pytest.raises(ValueError):
        p.with_battery(120)


def test_with_home_moves_the_origin() -> None:
    p = bundled_platform("indoor").with_home(58.39, 15.57)
    assert p.home == (58.39, 15.57)
    with pytest.raises(ValueError):
        p.with_home(95.0, 0.0)


def test_autopilot_parameters_tighten_speed_ceiling_and_fence() -> None:
    p = from_yaml("platform: x\nhome: [0, 0]\nlimits: {horizontal_speed: 5, vertical_speed: 2}\n"
                  "altitude_max: 50\n"
                  "autopilot_params: {WPNAV_SPEED: 300, WPNAV_SPEED_UP: 150, FENCE_ALT_MAX: 20,"
                  " FENCE_RADIUS: 30, SOME_OTHER: 7}\n")
    assert p.max_speed == (3.0, "WPNAV_SPEED")
    assert p.max_climb == 1.5 and p.max_descent == 2.0
    assert p.ceiling == (20.0, "FENCE_ALT_MAX")
    assert p.fence_reason((10.0, 10.0)) is None
    assert "FENCE_RADIUS" in (p.fence_reason((25.0, 25.0)) or "")
    loose = from_yaml("platform: x\nhome: [0, 0]\nlimits: {horizontal_speed: 5}\n"
                      "autopilot_params: {WPNAV_SPEED: 900}\n")
    assert loose.max_speed == (5.0, "limits.horizontal_speed")  # a looser parameter does not widen


def test_unbounded_platform_has_an_infinite_ceiling() -> None:
    p = from_yaml("platform: x\nhome: [0, 0]\n")
    assert math.isinf(p.ceiling[0])
    assert p.fence_reason((1e4, 1e4)) is None


@pytest.mark.parametrize("text, line, field", [
    ("platform: x\nhome: [0, 0]\ncolour: red\n", 3, "colour"),
    ("platform: x\nhome: [0, 0]\nspeeds: {slow: 3, standard: 2, fast: 4}\n", 3, "speeds"),
    ("platform: x\nhome: [0, 0]\ntasks: [take-off, teleport]\n", 3, "tasks"),
    ("platform: x\nhome: [0, 0]\nsensors:\n  camera: {fov_deg: 200}\n", 4, "sensors.camera.fov_deg"),
    ("platform: x\nhome: [0, 0]\nbattery: {capacity_s: 100, reserve_s: 200}\n", 3, "battery.reserve_s"),
    ("platform: x\nhome: [0, 0]\nprofile: underwater\n", 3, "profile"),
    ("platform: x\nhome: [0, 0]\nautopilot_params: {wpnav_speed: 3}\n", 3, "autopilot_params.wpnav_speed"),
    ("platform: x\nhome: [0, 0]\nenvelope: {box: {north_min: 5, north_max: 1, east_min: 0, east_max: 1}}\n",
     3, "envelope.box"),
])
def test_bad_platform_files_name_file_line_and_field(text: str, line: int, field: str) -> None:
    with pytest.raises(ConfigError) as info:
        from_yaml(text)
    assert info.value.file == "p.yaml" and info.value.line == line and info.value.field == field


def test_load_platform_reads_a_file_and_reports_a_missing_one(tmp_path: Path) -> None:
    f = tmp_path / "plat.yaml"
    f.write_text("platform: mine\nhome: [-35.36, 149.16]\nsensors: {camera: true, range_sensor: true}\n")
    p = load_platform(f)
    assert p.name == "mine" and p.range_sensor and p.sensors["camera"].fov_deg == 60.0
    with pytest.raises(ConfigError, match="cannot read"):
        load_platform(tmp_path / "nope.yaml")
