"""Tests of the state interface (seed 002 Sec. 3.1): any format in, any format out, converted once."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from autopilot_model.state import (
    StateInterface,
    euler_to_matrix,
    euler_to_quat,
    matrix_to_euler,
    matrix_to_quat,
    quat_to_euler,
    quat_to_matrix,
)

S = math.sqrt(0.5)
# (euler, quaternion, matrix) known triples, body -> NED, ZYX
KNOWN = [
    ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), ((1, 0, 0), (0, 1, 0), (0, 0, 1))),
    ((0.0, 0.0, math.pi / 2), (S, 0.0, 0.0, S), ((0, -1, 0), (1, 0, 0), (0, 0, 1))),  # heading east
    ((math.pi / 2, 0.0, 0.0), (S, S, 0.0, 0.0), ((1, 0, 0), (0, 0, -1), (0, 1, 0))),  # right wing down
    ((0.0, math.pi / 6, 0.0), (math.cos(math.pi / 12), 0.0, math.sin(math.pi / 12), 0.0),
     ((math.sqrt(3) / 2, 0, 0.5), (0, 1, 0), (-0.5, 0, math.sqrt(3) / 2))),  # nose up 30 deg
]


def rot_np(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Independent reference: Rz(yaw) @ Ry(pitch) @ Rx(roll)."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def same_quat(a: tuple, b: tuple, tol: float = 1e-12) -> bool:
    return max(abs(x - y) for x, y in zip(a, b, strict=True)) < tol or max(
        abs(x + y) for x, y in zip(a, b, strict=True)) < tol


@pytest.mark.parametrize("euler,quat,mat", KNOWN)
def test_known_attitudes(euler: tuple, quat: tuple, mat: tuple) -> None:
    assert same_quat(euler_to_quat(euler), quat)
    assert np.allclose(euler_to_matrix(euler), mat, atol=1e-12)
    assert np.allclose(quat_to_matrix(quat), mat, atol=1e-12)
    assert np.allclose(quat_to_euler(quat), euler, atol=1e-12)
    assert np.allclose(matrix_to_euler(mat), euler, atol=1e-12)
    assert same_quat(matrix_to_quat(mat), quat)
    # through the blackboard, every way round
    for write, value in (("set_euler", euler), ("set_quat", quat), ("set_rot_matrix", mat)):
        s = StateInterface()
        getattr(s, write)(value)
        assert np.allclose(s.euler, euler, atol=1e-12)
        assert same_quat(s.quat, quat)
        assert np.allclose(s.rot_matrix, mat, atol=1e-12)


def test_random_round_trips() -> None:
    rng = random.Random(7)
    for _ in range(500):
        e = (rng.uniform(-math.pi, math.pi), rng.uniform(-1.5, 1.5), rng.uniform(-math.pi, math.pi))
        ref = rot_np(*e)
        q = euler_to_quat(e)
        m = quat_to_matrix(q)
        assert np.allclose(m, ref, atol=1e-12)
        assert np.allclose(euler_to_matrix(e), ref, atol=1e-12)
        assert np.allclose(quat_to_euler(q), e, atol=1e-9)
        assert np.allclose(matrix_to_euler(m), e, atol=1e-9)
        q2 = matrix_to_quat(m)
        assert same_quat(q2, q, 1e-9) and q2[0] >= 0.0
        assert abs(sum(x * x for x in q2) - 1.0) < 1e-12


def test_quaternion_normalised_and_numpy_matrix_accepted() -> None:
    s = StateInterface()
    s.set_quat((2.0, 0.0, 0.0, 2.0))
    assert np.allclose(s.quat, (S, 0.0, 0.0, S))
    assert s.heading == pytest.approx(math.pi / 2)
    s.set_rot_matrix(rot_np(0.1, -0.2, 3.0))
    assert np.allclose(s.euler, (0.1, -0.2, 3.0))
    assert isinstance(s.rot_matrix, tuple) and all(isinstance(r, tuple) for r in s.rot_matrix)


def ecef(lat: float, lon: float, h: float) -> np.ndarray:
    """WGS84 geodetic -> ECEF, written out independently of pymap3d."""
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    la, lo = math.radians(lat), math.radians(lon)
    n = a / math.sqrt(1 - e2 * math.sin(la) ** 2)
    return np.array([(n + h) * math.cos(la) * math.cos(lo), (n + h) * math.cos(la) * math.sin(lo),
                     (n * (1 - e2) + h) * math.sin(la)])


def ned_of(lla: tuple, origin: tuple) -> np.ndarray:
    la, lo = math.radians(origin[0]), math.radians(origin[1])
    r = np.array([[-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)],
                  [-math.sin(lo), math.cos(lo), 0.0],
                  [-math.cos(la) * math.cos(lo), -math.cos(la) * math.sin(lo), -math.sin(la)]])
    return r @ (ecef(*lla) - ecef(*origin))


def test_ned_geodetic_known_values() -> None:
    """ArduPilot's flat-earth convention (taskflight_common.geo): 1e-7 deg of latitude = 0.011131884502 m."""
    s = StateInterface(origin=(0.0, 0.0, 100.0))
    s.set_position_ned((1000.0, 0.0, -50.0))
    lat, lon, alt = s.position_geodetic
    assert lat == pytest.approx(1000.0 / 0.011131884502145034 * 1e-7, abs=1e-12)
    assert lon == pytest.approx(0.0, abs=1e-12)
    assert alt == pytest.approx(150.0, abs=1e-9)
    s = StateInterface(origin=(60.0, 10.0, 0.0))
    s.set_position_ned((0.0, 1000.0, 0.0))
    lat, lon, alt = s.position_geodetic
    assert lat == pytest.approx(60.0, abs=1e-12)
    # a degree of longitude at 60 degrees is half as long as at the equator
    assert lon - 10.0 == pytest.approx(2 * 1000.0 / 0.011131884502145034 * 1e-7, rel=1e-9)


def test_ned_geodetic_round_trips() -> None:
    origin = (47.397742, 8.545594, 488.0)
    s = StateInterface(origin=origin)
    rng = random.Random(3)
    for _ in range(20):
        p = (rng.uniform(-3000, 3000), rng.uniform(-3000, 3000), rng.uniform(-300, 50))
        s.set_position_ned(p)
        lla = s.position_geodetic
        # independent check against WGS84: the flat-earth convention is within 0.4 % of the distance
        dist = math.hypot(p[0], p[1])
        assert np.linalg.norm(ned_of(lla, origin)[:2] - np.array(p[:2])) <= 0.004 * dist
        s.set_position_geodetic(lla)
        assert np.allclose(s.position_ned, p, atol=1e-6)
        assert s.alt_rel == pytest.approx(-p[2], abs=1e-6)
    s.set_position_geodetic(origin)
    assert np.allclose(s.position_ned, (0.0, 0.0, 0.0), atol=1e-9)


def test_set_origin_keeps_the_written_format() -> None:
    s = StateInterface(origin=(47.0, 8.0, 400.0))
    s.set_position_ned((100.0, 0.0, -10.0))
    s.set_origin((47.001, 8.0, 400.0))
    assert s.position_ned == (100.0, 0.0, -10.0)
    assert s.position_geodetic[0] > 47.001
    s.set_position_geodetic((47.0, 8.0, 410.0))
    assert s.position_ned[0] < -100.0
    s.set_origin((47.0, 8.0, 400.0))
    assert s.position_geodetic == (47.0, 8.0, 410.0)
    assert np.allclose(s.position_ned, (0.0, 0.0, -10.0), atol=1e-9)


def test_each_conversion_once_per_update() -> None:
    s = StateInterface(origin=(47.0, 8.0, 400.0))
    s.set_quat(euler_to_quat((0.1, 0.2, 0.3)))
    for _ in range(100):
        e = s.euler
        m = s.rot_matrix
        h = s.heading
    assert s.conversions["euler"] == 1 and s.conversions["matrix"] == 1
    assert e[2] == h == pytest.approx(0.3)
    assert m is s.rot_matrix  # the cached object, not a recomputation
    for _ in range(100):
        s.quat  # noqa: B018 (the written format: no conversion)
    assert s.conversions["quat"] == 0
    s.set_quat(euler_to_quat((0.1, 0.2, 0.4)))  # a new write invalidates
    assert s.heading == pytest.approx(0.4)
    assert s.conversions["euler"] == 2 and s.conversions["matrix"] == 1
    s.rot_matrix  # noqa: B018
    assert s.conversions["matrix"] == 2
    s.set_euler((0.0, 0.0, 1.0))
    for _ in range(100):
        s.quat  # noqa: B018
    assert s.conversions["quat"] == 1 and s.conversions["euler"] == 2
    # position: geodetic only on demand, once
    s.set_position_ned((10.0, 20.0, -30.0))
    for _ in range(100):
        s.position_geodetic  # noqa: B018
        assert s.alt_rel == 30.0
    assert s.conversions["geodetic"] == 1 and s.conversions["ned"] == 0
    s.set_position_geodetic((47.0, 8.0, 430.0))
    for _ in range(100):
        s.position_ned  # noqa: B018
    assert s.conversions["ned"] == 1 and s.conversions["geodetic"] == 1
    # a velocity write does not invalidate the attitude or the position
    s.set_velocity_ned((3.0, 4.0, 0.0))
    for _ in range(100):
        assert s.ground_speed == 5.0
    s.quat  # noqa: B018
    s.position_ned  # noqa: B018
    assert s.conversions == {"euler": 2, "quat": 1, "matrix": 2, "ned": 1, "geodetic": 1, "ground_speed": 1}
    assert s.conversions_total == 8


BAD_VECTORS = [(1.0, 2.0), (1.0, 2.0, 3.0, 4.0), (1.0, math.nan, 0.0), (math.inf, 0.0, 0.0), None, "abc",
               3.0, (1.0, "x", 2.0)]


def snapshot(s: StateInterface) -> tuple:
    return (s.position_ned, s.position_geodetic, s.quat, s.euler, s.rot_matrix, s.velocity_ned,
            s.acceleration_ned, s.body_rates, s.time_us, dict(s.conversions))


@pytest.mark.parametrize("bad", BAD_VECTORS)
def test_invalid_input_raises_and_changes_nothing(bad: object) -> None:
    s = StateInterface(origin=(47.0, 8.0, 400.0))
    s.update(1000, position_ned=(1.0, 2.0, -3.0), velocity_ned=(1.0, 0.0, 0.0), euler=(0.1, 0.2, 0.3),
             acceleration_ned=(0.0, 0.0, 1.0), body_rates=(0.01, 0.02, 0.03))
    before = snapshot(s)
    methods = ["set_position_ned", "set_position_geodetic", "set_euler", "set_velocity_ned",
               "set_acceleration_ned", "set_body_rates", "set_rot_matrix", "set_origin"]
    if bad != (1.0, 2.0, 3.0, 4.0):  # a valid (non-normalised) quaternion
        methods.append("set_quat")
    for method in methods:
        with pytest.raises(ValueError):
            getattr(s, method)(bad)
    if bad is not None:  # None = "not given" in update()
        with pytest.raises(ValueError):
            s.update(2000, position_ned=(5.0, 5.0, 5.0), velocity_ned=bad)  # all or nothing
    assert snapshot(s) == before


@pytest.mark.parametrize("bad", [
    (0.0, 0.0, 0.0, 0.0),  # zero quaternion
    (math.nan, 0.0, 0.0, 1.0),
])
def test_invalid_quaternion(bad: tuple) -> None:
    s = StateInterface()
    s.set_euler((0.1, 0.2, 0.3))
    with pytest.raises(ValueError):
        s.set_quat(bad)
    assert s.euler == (0.1, 0.2, 0.3)


@pytest.mark.parametrize("bad", [
    ((1, 0, 0), (0, 1, 0), (0, 0, -1)),  # reflection
    ((2, 0, 0), (0, 1, 0), (0, 0, 1)),  # not orthonormal
    ((1, 0, 0), (0, 1, 0)),  # 2 rows
    ((1, 0), (0, 1), (0, 0)),  # 2 columns
    np.eye(4),
])
def test_invalid_matrix(bad: object) -> None:
    s = StateInterface()
    s.set_euler((0.1, 0.2, 0.3))
    with pytest.raises(ValueError):
        s.set_rot_matrix(bad)
    assert s.euler == (0.1, 0.2, 0.3)


def test_invalid_latitude_and_time() -> None:
    s = StateInterface()
    with pytest.raises(ValueError):
        s.set_position_geodetic((91.0, 0.0, 0.0))
    with pytest.raises(ValueError):
        StateInterface(origin=(0.0, 0.0))
    with pytest.raises(ValueError):
        s.update("soon", velocity_ned=(1.0, 1.0, 1.0))  # type: ignore[arg-type]
    assert s.velocity_ned == (0.0, 0.0, 0.0) and s.time_us == 0


def test_update_writes_all_and_stamps_time() -> None:
    s = StateInterface(origin=(47.0, 8.0, 400.0))
    s.update(123456, position_geodetic=(47.0, 8.0, 410.0), quat=(1.0, 0.0, 0.0, 0.0),
             velocity_ned=(1.0, 2.0, 3.0), acceleration_ned=(0.0, 0.0, -9.8), body_rates=(0.1, 0.0, 0.0))
    assert s.time_us == 123456
    assert s.alt_rel == pytest.approx(10.0)
    assert s.velocity_ned == (1.0, 2.0, 3.0) and s.acceleration_ned == (0.0, 0.0, -9.8)
    assert s.body_rates == (0.1, 0.0, 0.0) and s.euler == (0.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        s.update(1, euler=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0))
