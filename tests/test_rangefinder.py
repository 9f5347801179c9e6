"""The model's terrain and downward range finder (ArduCopter's RNGFND1_* and DISTANCE_SENSOR), the companion's
reading of it, the V_GROUND flight mode, and delegation's refusal of follow-ground without a range finder."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from autopilot_model.airframe import DEFAULT_AIRFRAME, load_airframe
from autopilot_model.params import ParamError
from companion.flight import CommandQueue, FlightCommand, Limits
from companion.flight.commands import CommandError, EndCondition, HorizontalChannel, VerticalChannel
from companion.flight.events import EventKind
from companion.flight.setpoint import VehicleState
from companion.link.mirror import VehicleMirror
from companion.node import range_status
from companion.tst.delegation import delegate
from companion.tst.platform import bundled_platform
from companion.tst.spec import mission_from_yaml
from taskflight_common.yamlio import ConfigError


@pytest.fixture(scope="module")
def sitl(tmp_path_factory: pytest.TempPathFactory) -> Any:
    from autopilot_model.sitl import Sitl

    tmp = tmp_path_factory.mktemp("rangefinder")
    af = tmp / "hill.yaml"
    af.write_text(DEFAULT_AIRFRAME.read_text()
                  + "terrain:\n  hills:\n    - {north: 0, east: 0, height: 2.0, sigma: 5}\n")
    s = Sitl(urls=["udpin:127.0.0.1:0"], state_dir=tmp, persist=False, airframe=af)
    yield s
    s.close()


def test_distance_sensor_bytes_decode_as_arducopter_sends_them(sitl: Any) -> None:
    v, link = sitl.vehicle, sitl.link.rangefinder
    assert link.distance_sensor() is None  # RNGFND1_TYPE 0 (ArduCopter's default): nothing sent
    v.params.set("RNGFND1_TYPE", 100)
    v.params.set("RNGFND1_MAX", 40.0)
    v.world.x[2] = -12.0  # 12 m up, over a 2 m hill: 10 m + ground clearance
    raw = link.distance_sensor().pack(mavlink2.MAVLink(None, 1, 1))
    msg = mavlink2.MAVLink(None).decode(bytearray(raw))
    assert msg.get_type() == "DISTANCE_SENSOR"
    assert msg.orientation == mavlink2.MAV_SENSOR_ROTATION_PITCH_270 == 25
    assert msg.min_distance == 20 and msg.max_distance == 4000
    assert abs(msg.current_distance - 1010) <= 10  # cm, 2 cm noise
    assert msg.type == mavlink2.MAV_DISTANCE_SENSOR_LASER and msg.id == 0
    rf = mavlink2.MAVLink(None).decode(bytearray(link.rangefinder().pack(mavlink2.MAVLink(None, 1, 1))))
    assert abs(rf.distance - 10.1) < 0.1
    assert "DISTANCE_SENSOR" in sitl.link.streams.builders
    v.params.set("RNGFND1_TYPE", 0)


def test_rngfnd1_parameters_are_validated_and_a_refusal_changes_nothing(sitl: Any) -> None:
    p = sitl.vehicle.params
    for name, bad, why in (("RNGFND1_TYPE", 8, "not supported"), ("RNGFND1_ORIENT", 0, "out of range"),
                           ("RNGFND1_MAX", -1, "out of range"), ("RNGFND1_TYPE", 1.5, "integer")):
        before = p.get(name)
        with pytest.raises(ParamError, match=why):
            p.set(name, bad)
        assert p.get(name) == before
    assert p.get("RNGFND1_ORIENT") == 25 and p.get("RNGFND1_MIN") == 0.2


def test_terrain_from_yaml_and_a_bad_field_names_file_line_and_field(tmp_path: Path) -> None:
    good = tmp_path / "good.yaml"
    good.write_text(DEFAULT_AIRFRAME.read_text() + "terrain:\n  hills:\n"
                    "    - {north: 10, east: 0, height: 4, sigma: 3}\n"
                    "  grid: {north0: -10, east0: -10, spacing: 10,\n"
                    "         heights: [[0, 0, 0], [0, 2, 0]]}\n")
    t = load_airframe(good).terrain
    assert t.height(10, 0) == pytest.approx(4.0 + 2.0)  # the hill plus the grid's edge (beyond its last row)
    assert t.height(-5, 0) == pytest.approx(1.0, abs=1e-3)  # half-way between two rows, bilinear
    assert t.height(500, 500) == pytest.approx(0.0)
    assert load_airframe(DEFAULT_AIRFRAME).terrain.flat
    n = len(DEFAULT_AIRFRAME.read_text().splitlines())
    bad = tmp_path / "bad.yaml"
    bad.write_text(DEFAULT_AIRFRAME.read_text() + "terrain:\n  hills:\n    - {north: 10, east: 0, height: 4,"
                   " sigma: -3}\n")
    with pytest.raises(ConfigError) as err:
        load_airframe(bad)
    assert str(bad) in str(err.value) and "terrain.hills[0].sigma" in str(err.value)
    assert err.value.line == n + 3
    ragged = tmp_path / "ragged.yaml"
    ragged.write_text(DEFAULT_AIRFRAME.read_text() + "terrain:\n  grid:\n    spacing: 5\n    heights:\n"
                      "      - [0, 1]\n      - [0]\n")
    with pytest.raises(ConfigError, match=r"terrain\.grid\.heights\[1\]"):
        load_airframe(ragged)


def test_the_mirror_reads_the_downward_distance_sensor_age_stamped() -> None:
    mav = mavlink2.MAVLink(None, 1, 1)
    mirror = VehicleMirror()
    mirror.update(mav.local_position_ned_encode(1000, 0, 0, -9.0, 0, 0, 0), 0.0)
    mirror.update(mav.distance_sensor_encode(1500, 20, 4000, 700, 0, 0, 25, 0), 0.0)
    mirror.update(mav.distance_sensor_encode(1600, 20, 4000, 300, 0, 1, 0, 0), 0.0)  # forward: not ours
    r = range_status(mirror.snapshot(), 2.0)
    assert r is not None and r.distance_m == 7.0 and r.age_s == pytest.approx(0.5)
    assert r.in_range and r.ground_alt == pytest.approx(2.0)


def _fly(queue: CommandQueue, ground_alt: float | None, seconds: float, age: float = 0.1,
         t0: float = 0.0) -> float:
    t, alt = t0, None
    for _ in range(int(seconds * 20)):
        t += 0.05
        ref = queue.reference
        p = ref.p if ref is not None else (0.0, 0.0, -10.0)
        vs = VehicleState((p[0], p[1], p[2]), ground_alt=ground_alt,
                          ground_age_s=age if ground_alt is not None else None)
        sp = queue.tick(t, vs)
        alt = -sp.p[2]
    assert alt is not None
    return t


def test_v_ground_flies_the_measured_height_and_fails_when_the_range_is_lost() -> None:
    with pytest.raises(CommandError, match=r"vertical\.altitude"):
        VerticalChannel("GROUND", altitude=0.0)
    queue = CommandQueue(Limits())
    cmd = FlightCommand(HorizontalChannel("POS", north=30.0, east=0.0, speed=2.0),
                        VerticalChannel("GROUND", altitude=7.0), end=EndCondition(e_h=True, e_v=True))
    queue.add_commands([cmd])
    queue.run()
    t = _fly(queue, 3.0, 8.0)  # ground at 3 m: the goal is 10 m up
    assert queue.reference is not None and -queue.reference.p[2] == pytest.approx(10.0, abs=0.05)
    t = _fly(queue, 5.0, 6.0, t0=t)  # a rise of 2 m: up to 12 m
    assert -queue.reference.p[2] == pytest.approx(12.0, abs=0.05)
    seq = queue.events.last_seq
    _fly(queue, 5.0, 5.0, age=2.0, t0=t)  # the readings stop (stale): altitude held, then the command fails
    assert -queue.reference.p[2] == pytest.approx(12.0, abs=0.3)
    failed = [e for e in queue.events.since(seq) if e.kind is EventKind.FAILED]
    assert failed and "no fresh downward range-finder reading" in failed[0].detail


def test_a_platform_without_a_range_finder_refuses_follow_ground_naming_the_node() -> None:
    indoor = bundled_platform("indoor")
    assert not indoor.range_sensor
    lat, lon = indoor.home[0], indoor.home[1]
    m = mission_from_yaml(f"""
mission: fg
tree:
  type: S
  id: root
  children:
    - {{type: take-off, id: up}}
    - {{type: fly-to, id: hop, params: {{position: [{lat}, {lon}, 3.0], follow_ground_flag: true,
        follow_ground_altitude: 3.0}}}}
""")
    d = delegate(m, indoor)
    assert not d.accepted
    assert any("node hop (fly-to)" in r and "no range sensor" in r for r in d.reasons), d.reasons
    assert delegate(m, bundled_platform("outdoor")).accepted


def test_a_tilted_reading_is_made_vertical_as_arducopter_does() -> None:
    mav = mavlink2.MAVLink(None, 1, 1)
    mirror = VehicleMirror()
    mirror.update(mav.local_position_ned_encode(1000, 0, 0, -7.0, 0, 0, 0), 0.0)
    mirror.update(mav.attitude_encode(1000, 0.0, 0.5, 0.0, 0, 0, 0), 0.0)  # pitched 0.5 rad
    mirror.update(mav.distance_sensor_encode(1100, 20, 4000, 800, 0, 0, 25, 0), 0.0)
    r = range_status(mirror.snapshot(), 1.2)
    assert r is not None and r.ground_alt == pytest.approx(7.0 - 8.0 * math.cos(0.5))
