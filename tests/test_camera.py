"""The simulated downward camera and its scenario file (seed 000 Sec. VI-E data_uuid, Sec. VII)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from companion.behaviors.beliefs import BeliefMemory
from companion.behaviors.processes import ProcessManager
from companion.flight.setpoint import VehicleState
from companion.sensing.camera import DownwardCamera
from companion.sensing.scenario import Scenario, SceneObject
from taskflight_common.geo import ned_to_geodetic
from taskflight_common.yamlio import ConfigError

HOME = (58.3950, 15.5720, 0.0)


class ScriptedVehicle:
    """A fake vehicle: the state the test sets (not under test)."""

    def __init__(self, state: VehicleState | None = None) -> None:
        self.state = state

    def at(self, n: float, e: float, alt: float, yaw: float = 0.0) -> None:
        self.state = VehicleState(p=(n, e, -alt), yaw=yaw)

    def __call__(self) -> VehicleState | None:
        return self.state


def _camera(objects: list[SceneObject], fov=60.0,
            **kw) -> tuple[DownwardCamera, BeliefMemory, ScriptedVehicle]:
    beliefs = BeliefMemory()
    vehicle = ScriptedVehicle()
    cam = DownwardCamera(Scenario(objects), fov, beliefs, vehicle, **kw)
    cam.start()
    return cam, beliefs, vehicle


# --- the scenario file -----------------------------------------------------------------------------
def test_scenario_file_with_local_positions_and_geopoints(tmp_path: Path) -> None:
    lat, lon, _ = ned_to_geodetic(HOME, 20.0, -8.0, 0.0)
    f = tmp_path / "scenario.yaml"
    f.write_text(f"home: [{HOME[0]}, {HOME[1]}]\n"
                 "objects:\n"
                 "  - {id: 7, class: person, position: [12.0, 8.5]}\n"
                 f"  - {{id: car_1, class: car, geopoint: [{lat:.9f}, {lon:.9f}]}}\n"
                 "  - {id: 9, class: person, position: [1.0, 2.0, -0.5]}\n")
    sc = Scenario.load(f)
    assert len(sc) == 3
    assert sc.objects[7] == SceneObject(7, "person", 12.0, 8.5, 0.0)
    car = sc.objects["car_1"]
    assert (car.n, car.e) == pytest.approx((20.0, -8.0), abs=1e-3)
    assert sc.objects[9].position == (1.0, 2.0, -0.5)


def test_the_vehicle_home_is_used_when_the_file_has_none() -> None:
    lat, lon, _ = ned_to_geodetic(HOME, -5.0, 3.0, 0.0)
    text = f"objects:\n  - {{id: 1, class: person, geopoint: [{lat:.9f}, {lon:.9f}]}}\n"
    sc = Scenario.from_text(text, home=HOME)
    assert (sc.objects[1].n, sc.objects[1].e) == pytest.approx((-5.0, 3.0), abs=1e-3)


@pytest.mark.parametrize(("text", "line", "field", "reason"), [
    ("objects:\n  - {id: 1, class: person, position: [1, 2]}\n  - {id: 1, class: car, position: [3, 4]}\n",
     3, "objects[1].id", "already used"),
    ("objects:\n  - id: 1\n    class: person\n    colour: red\n    position: [1, 2]\n",
     4, "objects[0].colour", "unknown field"),
    ("objects:\n  - {id: 1, class: person, geopoint: [58.4, 15.6]}\n", 2, "objects[0].geopoint", "home"),
    ("objects:\n  - {id: 1, class: person}\n", 2, "objects[0]", "exactly one"),
    ("objects:\n  - {id: 1, class: 'a person', position: [1, 2]}\n", 2, "objects[0].class", "symbol"),
    ("objects:\n  - {id: 1, class: person, position: [1, x]}\n", 2, "objects[0].position", "numbers"),
    ("home: [95, 15]\nobjects: []\n", 1, "home", "out of range"),
    ("object:\n  - {id: 1}\n", 1, "object", "unknown field"),
], ids=["duplicate id", "unknown field", "geopoint without home", "no position", "bad class", "bad position",
        "bad home", "unknown top field"])
def test_scenario_errors_name_file_line_and_field(tmp_path: Path, text, line, field, reason) -> None:
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    with pytest.raises(ConfigError) as info:
        Scenario.load(f)
    err = info.value
    assert (err.file, err.line, err.field) == (str(f), line, field)
    assert reason in err.reason
    assert str(err).startswith(f"{f}:{line}: {field}:")


# --- the camera ------------------------------------------------------------------------------------
def test_an_object_in_the_footprint_becomes_beliefs_and_leaves_visible_when_out_of_view() -> None:
    cam, beliefs, vehicle = _camera([SceneObject(7, "person", 10.0, 0.0)])
    assert cam.name == "camera"
    vehicle.at(0.0, 0.0, 10.0)  # half footprint 5.77 m: the person 10 m north is outside
    cam.tick(1.0)
    assert not beliefs.holds("visible(7)")
    assert len(beliefs) == 0
    vehicle.at(6.0, 0.0, 10.0)
    cam.tick(2.0)
    assert beliefs.holds("visible(7)")
    assert beliefs.holds("object(7, person)")
    assert beliefs.holds("position(7, (10.0, 0.0, 0.0))")
    assert beliefs.consult("visible(?x), object(?x, person)") == [{"x": 7}]
    assert [(d.t_s, d.object_id, d.cls) for d in cam.detections] == [(2.0, 7, "person")]
    assert cam.detections[0].vehicle == pytest.approx((6.0, 0.0, 10.0))
    cam.tick(3.0)  # still in view: no second detection
    assert len(cam.detections) == 1
    vehicle.at(30.0, 0.0, 10.0)
    cam.tick(4.0)
    assert not beliefs.holds("visible(7)")
    assert beliefs.holds("object(7, person)")  # the robot remembers
    assert beliefs.holds("position(7, (10.0, 0.0, 0.0))")
    assert cam.visible == frozenset()


def test_the_footprint_grows_with_altitude() -> None:
    cam, beliefs, vehicle = _camera([SceneObject(1, "person", 8.0, 0.0)], fov=60.0)
    vehicle.at(0.0, 0.0, 10.0)  # half 5.77 m
    cam.tick(1.0)
    assert not beliefs.holds("visible(1)")
    vehicle.at(0.0, 0.0, 15.0)  # half 8.66 m
    cam.tick(2.0)
    assert beliefs.holds("visible(1)")


def test_heading_turns_a_rectangular_footprint() -> None:
    # 90 deg across the heading (half 10 m at 10 m), 30 deg along it (half 2.68 m)
    cam, beliefs, vehicle = _camera([SceneObject(1, "person", 5.0, 0.0)], fov=(90.0, 30.0))
    vehicle.at(0.0, 0.0, 10.0, yaw=0.0)  # heading north: the person is 5 m ahead, outside
    cam.tick(1.0)
    assert not beliefs.holds("visible(1)")
    vehicle.at(0.0, 0.0, 10.0, yaw=math.pi / 2)  # heading east: the person is 5 m to the side
    cam.tick(2.0)
    assert beliefs.holds("visible(1)")
    corners = cam.view_polygon(vehicle.state)
    assert sorted(round(c[0], 6) + 0.0 for c in corners) == pytest.approx([-10, -10, 10, 10])


def test_nothing_is_seen_beyond_the_maximum_range_or_without_a_state() -> None:
    cam, beliefs, vehicle = _camera([SceneObject(1, "person", 0.0, 0.0)], max_range_m=50.0)
    vehicle.at(0.0, 0.0, 60.0)
    cam.tick(1.0)
    assert not beliefs.holds("visible(1)")
    vehicle.at(0.0, 0.0, 40.0)
    cam.tick(2.0)
    assert beliefs.holds("visible(1)")
    vehicle.state = None
    cam.tick(3.0)
    assert not beliefs.holds("visible(1)")
    vehicle.at(0.0, 0.0, 0.1)  # on the ground: below min_altitude
    cam.tick(4.0)
    assert not beliefs.holds("visible(1)")


def test_nothing_is_seen_while_stopped_and_stopping_retracts_visible() -> None:
    beliefs = BeliefMemory()
    vehicle = ScriptedVehicle()
    vehicle.at(0.0, 0.0, 10.0)
    cam = DownwardCamera(Scenario([SceneObject(1, "person", 1.0, 1.0)]), 60.0, beliefs, vehicle)
    cam.tick(1.0)  # never started
    assert len(beliefs) == 0 and cam.detections == []
    cam.start()
    cam.tick(2.0)
    assert beliefs.holds("visible(1)")
    cam.stop()
    assert not beliefs.holds("visible(1)")
    assert beliefs.holds("object(1, person)")
    cam.tick(3.0)
    assert not beliefs.holds("visible(1)")
    assert len(cam.detections) == 1


def test_detections_are_labelled_with_the_scans_data_uuid() -> None:
    objects = [SceneObject(7, "person", 0.0, 0.0), SceneObject(8, "car", 50.0, 0.0)]
    cam, _, vehicle = _camera(objects, data_uuid="scan-1")
    vehicle.at(0.0, 0.0, 10.0)
    cam.tick(1.0)
    cam.data_uuid = "scan-2"
    vehicle.at(50.0, 0.0, 10.0)
    cam.tick(2.0)
    cam.data_uuid = None
    vehicle.at(0.0, 0.0, 10.0)  # 7 comes back into view: a new detection, unlabelled
    cam.tick(3.0)
    assert [d.object_id for d in cam.results("scan-1")] == [7]
    assert [d.object_id for d in cam.results("scan-2")] == [8]
    assert [d.data_uuid for d in cam.detections] == ["scan-1", "scan-2", None]
    assert cam.detections[1].to_dict()["data_uuid"] == "scan-2"
    assert cam.status()["detections"] == 3
    with pytest.raises(ValueError):
        cam.data_uuid = 5  # type: ignore[assignment]


def test_the_camera_runs_as_an_execution_process() -> None:
    beliefs = BeliefMemory()
    vehicle = ScriptedVehicle()
    vehicle.at(2.0, 2.0, 8.0)
    cam = DownwardCamera(Scenario([SceneObject(3, "person", 0.0, 0.0)]), 60.0, beliefs, vehicle)
    now = [0.0]
    pm = ProcessManager([cam], now=lambda: now[0])
    pm.tick(1.0)
    assert not beliefs.holds("visible(3)")
    pm.request_start(["camera"], by="scan-ground")
    pm.tick(2.0)
    assert beliefs.holds("visible(3)")
    pm.release(["camera"], by="scan-ground")
    assert pm.collect() == ["camera"]
    assert not beliefs.holds("visible(3)")


def test_bad_camera_parameters_are_refused() -> None:
    sc = Scenario([SceneObject(1, "person", 0.0, 0.0)])
    with pytest.raises(ValueError):
        DownwardCamera(sc, 190.0, BeliefMemory(), ScriptedVehicle())
    with pytest.raises(ValueError):
        DownwardCamera(sc, 60.0, BeliefMemory(), ScriptedVehicle(), max_range_m=0.0)
    with pytest.raises(ValueError):
        Scenario([SceneObject(1, "person", 0.0, 0.0), SceneObject(1, "car", 1.0, 1.0)])


def test_the_example_scenario_loads() -> None:
    sc = Scenario.load(Path(__file__).resolve().parents[1] / "mission_specs" / "scenario_example.yaml")
    assert {o.id: o.cls for o in sc} == {7: "person", 8: "person", 12: "car"}
