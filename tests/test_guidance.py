"""Tests of the setpoint generator and its envelope (seed 000 Sec. IV-D, Fig. 9)."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from autopilot_model.modules.guidance import Envelope, SetpointGenerator

LIMITS = dict(max_speed_h=8.0, max_speed_up=3.0, max_speed_down=2.0, max_accel_h=3.0, max_accel_v=2.0,
              max_yaw_rate=math.radians(90.0), max_yaw_accel=math.radians(180.0))
BOX = (-30.0, 30.0, -20.0, 20.0)
HEXAGON = [(-30.0, -10.0), (-10.0, -25.0), (20.0, -20.0), (35.0, 0.0), (15.0, 25.0), (-20.0, 20.0)]
L_SHAPE = [(-30.0, -20.0), (30.0, -20.0), (30.0, 0.0), (0.0, 0.0), (0.0, 20.0), (-30.0, 20.0)]
FLOOR, CEILING = 2.0, 25.0


def make_env(kind: str) -> Envelope:
    if kind == "box":
        return Envelope(box=BOX, alt_floor=FLOOR, alt_ceiling=CEILING, **LIMITS)
    poly = HEXAGON if kind == "hexagon" else L_SHAPE
    return Envelope(polygon=poly, alt_floor=FLOOR, alt_ceiling=CEILING, **LIMITS)


def wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class Checker:
    """Steps a generator and checks continuity (the step bounds) on every step."""

    def __init__(self, g: SetpointGenerator, env: Envelope) -> None:
        self.g, self.env = g, env
        self.dt = g.dt
        self.points: list[tuple[float, float, float]] = [g.p]
        self.steps = 0
        self.limit_steps = 0

    def step(self, n: int = 1) -> None:
        g, env, dt = self.g, self.env, self.dt
        tol = 1e-9
        for _ in range(n):
            p0, v0, y0, r0 = g.p, g.v, g.yaw, g.yaw_rate
            g.update()
            p1, v1, a1 = g.p, g.v, g.a
            dph = math.hypot(p1[0] - p0[0], p1[1] - p0[1])
            dpv = p1[2] - p0[2]
            dvh = math.hypot(v1[0] - v0[0], v1[1] - v0[1])
            dvv = abs(v1[2] - v0[2])
            assert dph <= env.max_speed_h * dt + tol, (self.steps, dph)
            assert -env.max_speed_up * dt - tol <= dpv <= env.max_speed_down * dt + tol, (self.steps, dpv)
            assert dvh <= env.max_accel_h * dt + tol, (self.steps, dvh, v0, v1)
            assert dvv <= env.max_accel_v * dt + tol, (self.steps, dvv)
            assert math.hypot(v1[0], v1[1]) <= env.max_speed_h + tol
            assert -env.max_speed_up - tol <= v1[2] <= env.max_speed_down + tol
            for i in range(3):  # a is the acceleration actually applied
                assert abs(a1[i] - (v1[i] - v0[i]) / dt) <= 1e-6
            assert -math.pi <= g.yaw <= math.pi
            assert abs(wrap(g.yaw - y0)) <= env.max_yaw_rate * dt + tol, (self.steps, g.yaw, y0)
            assert abs(g.yaw_rate - r0) <= env.max_yaw_accel * dt + tol
            assert abs(g.yaw_rate) <= env.max_yaw_rate + tol
            self.points.append(p1)
            self.steps += 1
            self.limit_steps += g.limit_reached

    def assert_inside(self, tol: float = 1e-9) -> None:
        pts = np.asarray(self.points)
        alt = -pts[:, 2]
        assert alt.min() >= FLOOR - tol and alt.max() <= CEILING + tol, (alt.min(), alt.max())
        if self.env.shape is None:
            assert pts[:, 0].min() >= BOX[0] - tol and pts[:, 0].max() <= BOX[1] + tol
            assert pts[:, 1].min() >= BOX[2] - tol and pts[:, 1].max() <= BOX[3] + tol
        else:
            d = shapely.distance(self.env.shape, shapely.points(pts[:, 0], pts[:, 1]))
            assert d.max() <= tol, f"left the polygon by {d.max()} m at {pts[int(np.argmax(d))]}"
        # the braking bounds did the work, not the final clamp
        assert self.g.clamp_max <= 1e-6, self.g.clamp_max


@pytest.mark.parametrize("kind,dt", [("box", 0.01), ("hexagon", 0.01), ("l_shape", 0.01), ("box", 0.002)])
def test_random_targets_continuous_and_inside(kind: str, dt: float) -> None:
    """1000 random target changes at random times: P_d never jumps and never leaves P_env."""
    rng = random.Random(1234 + len(kind))
    env = make_env(kind)
    g = SetpointGenerator(env, dt)
    g.reset((0.0, 0.0, -10.0), (0.0, 0.0, 0.0), 0.3)
    c = Checker(g, env)
    changes = 1000 if dt == 0.01 else 150
    kinds = {"pos": 0, "vel": 0, "acc": 0, "hold": 0, "yaw": 0, "yaw_rate": 0}
    unreachable = 0
    for _ in range(changes):
        r = rng.random()
        if r < 0.35:
            p = (rng.uniform(-60, 60), rng.uniform(-45, 45), -rng.uniform(-10, 40))
            speed = rng.choice([None, rng.uniform(0.1, 15.0), 1e6])
            end = rng.choice([0.0, 0.0, 0.0, rng.uniform(0.0, 5.0)])
            g.set_position_target(p, speed=speed, end_speed=end)
            assert g.target_unreachable == (not env.contains(p, tol=0.0))
            unreachable += g.target_unreachable
            kinds["pos"] += 1
        elif r < 0.6:
            g.set_velocity_target((rng.uniform(-15, 15), rng.uniform(-15, 15), rng.uniform(-6, 6)))
            kinds["vel"] += 1
        elif r < 0.7:
            g.set_acceleration_target((rng.uniform(-10, 10), rng.uniform(-10, 10), rng.uniform(-5, 5)))
            kinds["acc"] += 1
        elif r < 0.8:
            g.hold()
            kinds["hold"] += 1
        elif r < 0.9:
            g.set_yaw_target(rng.uniform(-10, 10), rng.choice([None, rng.uniform(0.05, 5.0)]))
            kinds["yaw"] += 1
        else:
            g.set_yaw_rate_target(rng.uniform(-5, 5))
            kinds["yaw_rate"] += 1
        c.step(rng.choice([1, 2, 5, rng.randint(1, int(2 / dt)), rng.randint(1, int(6 / dt))]))
    c.assert_inside()
    assert min(kinds.values()) > 0 and unreachable > 0
    assert c.limit_steps > 100  # the fences were actually hit


def fly_to(g: SetpointGenerator, c: Checker, p: tuple[float, float, float], timeout_s: float, **kw: float,
           ) -> int:
    g.set_position_target(p, **kw)
    n = 0
    while not g.at_target:
        c.step()
        n += 1
        assert n * g.dt < timeout_s, f"did not reach {p}: at {g.p}"
    return n


@pytest.mark.parametrize("dt", [0.002, 0.01, 0.05])
def test_position_target_reached_exactly(dt: float) -> None:
    env = make_env("box")
    g = SetpointGenerator(env, dt)
    g.reset((0.0, 0.0, -5.0))
    c = Checker(g, env)
    for target in [(12.3456, -7.89, -11.1), (-3.0, 4.0, -11.1), (-3.0, 4.0, -3.3), (25.0, 19.0, -20.0)]:
        fly_to(g, c, target, 60.0)
        assert g.p == target and g.v == (0.0, 0.0, 0.0) and not g.target_unreachable
        c.step(20)  # and stays there
        assert g.p == target and g.at_target
    c.assert_inside()


def test_at_target_not_reset_by_repeated_target() -> None:
    """A stream repeating the same setpoint (MAVLink) keeps the end flag."""
    g = SetpointGenerator(make_env("box"), 0.01)
    g.reset((0.0, 0.0, -5.0))
    g.set_position_target((1.0, 1.0, -5.0))
    for _ in range(1000):
        g.update()
    assert g.at_target
    g.set_position_target((1.0, 1.0, -5.0))
    assert g.at_target
    g.set_position_target((1.0, 2.0, -5.0))
    assert not g.at_target


def test_straight_line_3d() -> None:
    """Horizontal and vertical motion together fly the straight line, both channels within limits."""
    env = make_env("box")
    for dt in (0.002, 0.02):
        g = SetpointGenerator(env, dt)
        start, end = (-20.0, -15.0, -3.0), (25.0, 10.0, -24.0)
        g.reset(start)
        c = Checker(g, env)
        n = fly_to(g, c, end, 60.0)
        a = np.asarray(start)
        u = np.asarray(end) - a
        u /= np.linalg.norm(u)
        pts = np.asarray(c.points)
        off = np.linalg.norm((pts - a) - np.outer((pts - a) @ u, u), axis=1)
        assert off.max() < 1e-9, off.max()
        # the vertical channel is the limiting one here (21 m up at 3 m/s vs 51 m at 8 m/s)
        vmax_v = max(-v for v in np.diff(pts[:, 2]) / dt)
        assert vmax_v == pytest.approx(env.max_speed_up, rel=1e-6)
        assert n * dt < 15.0


def test_speed_parameter_and_absurd_speed() -> None:
    env = make_env("box")
    g = SetpointGenerator(env, 0.01)
    g.reset((0.0, 0.0, -10.0))
    c = Checker(g, env)
    g.set_position_target((25.0, 0.0, -10.0), speed=2.0)
    c.step(500)
    assert max(math.hypot(*p) for p in np.diff(np.asarray(c.points)[:, :2], axis=0) / 0.01) <= 2.0 + 1e-9
    assert not g.limit_reached
    fly_to(g, c, (-25.0, 0.0, -10.0), 60.0, speed=1e9)  # absurd: capped by the envelope
    assert g.p == (-25.0, 0.0, -10.0)
    with pytest.raises(ValueError):
        g.set_position_target((0.0, 0.0, -10.0), speed=-1.0)
    with pytest.raises(ValueError):
        g.set_position_target((0.0, math.nan, -10.0))
    with pytest.raises(ValueError):
        g.set_velocity_target((1.0, 2.0))
    assert g.p == (-25.0, 0.0, -10.0) and g.target == (-25.0, 0.0, -10.0)  # unchanged
    c.assert_inside()


@pytest.mark.parametrize("kind", ["box", "hexagon"])
def test_braking_before_fence(kind: str) -> None:
    """A velocity target toward the fence stops before it (limit_reached); the same for the ceiling."""
    env = make_env(kind)
    g = SetpointGenerator(env, 0.002)
    g.reset((0.0, 0.0, -10.0))
    c = Checker(g, env)
    g.set_velocity_target((20.0, 0.0, 0.0))  # absurd speed, toward north
    c.step(int(20 / g.dt))
    assert g.limit_reached
    assert g.v == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)
    fence_n = BOX[1] if kind == "box" else 35.0  # the hexagon's vertex (35, 0)
    assert g.p[0] == pytest.approx(fence_n, abs=1e-3)
    assert g.p[0] <= fence_n + 1e-9
    # it braked before the fence: the last 0.5 s were decelerating
    vs = np.diff(np.asarray(c.points)[:, 0]) / g.dt
    assert vs.max() == pytest.approx(env.max_speed_h, rel=1e-3)
    g.set_velocity_target((0.0, 0.0, -10.0))  # up into the ceiling
    c.step(int(20 / g.dt))
    assert g.limit_reached and -g.p[2] == pytest.approx(CEILING, abs=1e-3)
    c.assert_inside()


def test_slides_along_wall() -> None:
    """A velocity target diagonal into a wall stops the normal component and keeps the tangential one."""
    env = make_env("box")
    g = SetpointGenerator(env, 0.01)
    g.reset((20.0, -15.0, -10.0))
    c = Checker(g, env)
    g.set_velocity_target((3.0, 3.0, 0.0))
    c.step(500)
    assert g.p[0] == pytest.approx(BOX[1], abs=1e-3)
    assert g.v[1] == pytest.approx(3.0) or g.p[1] == pytest.approx(BOX[3], abs=1e-3)
    assert g.limit_reached
    c.assert_inside()


@pytest.mark.parametrize("kind", ["box", "hexagon"])
def test_target_outside_envelope(kind: str) -> None:
    env = make_env(kind)
    g = SetpointGenerator(env, 0.01)
    g.reset((0.0, 0.0, -10.0))
    c = Checker(g, env)
    g.set_position_target((100.0, 0.0, -50.0))
    assert g.target_unreachable
    nearest, outside = env.nearest_inside((100.0, 0.0, -50.0))
    assert outside and -nearest[2] == CEILING
    while not g.at_target:
        c.step()
        assert c.steps < 10000
    assert g.p == nearest and g.target_unreachable
    assert env.contains(g.p)
    if kind == "box":
        assert g.p == (BOX[1], 0.0, -CEILING)
    g.set_position_target((0.0, 0.0, -10.0))
    assert not g.target_unreachable
    c.assert_inside()


def test_target_on_polygon_boundary_is_reachable() -> None:
    env = make_env("hexagon")
    g = SetpointGenerator(env, 0.01)
    g.reset((0.0, 0.0, -10.0))
    c = Checker(g, env)
    fly_to(g, c, (35.0, 0.0, -10.0), 60.0)  # a vertex
    assert g.p == (35.0, 0.0, -10.0) and not g.target_unreachable
    fly_to(g, c, (-20.0, 20.0 - 35.0 * 0.0, -10.0), 60.0)  # another vertex, across the polygon
    assert not g.target_unreachable
    c.assert_inside()


def test_mid_flight_switches_are_continuous() -> None:
    """Position -> new position -> velocity -> hold -> acceleration in mid-flight: no jumps, exact hold."""
    env = make_env("box")
    g = SetpointGenerator(env, 0.002)
    g.reset((0.0, 0.0, -10.0))
    c = Checker(g, env)
    g.set_position_target((25.0, 15.0, -20.0))
    c.step(1000)
    g.set_position_target((-25.0, -15.0, -5.0))  # reverse while flying fast
    c.step(1000)
    g.set_velocity_target((0.0, 5.0, -1.0))
    c.step(500)
    g.hold()
    while not g.at_target:
        c.step()
        assert c.steps < 10000
    held = g.p
    c.step(100)
    assert g.p == held and g.v == (0.0, 0.0, 0.0)
    g.set_acceleration_target((1.0, -1.0, 0.0))
    c.step(1000)
    assert g.a[0] == pytest.approx(1.0) and g.a[1] == pytest.approx(-1.0)
    c.assert_inside()


def test_end_speed_passes_target() -> None:
    env = make_env("box")
    g = SetpointGenerator(env, 0.01)
    g.reset((-20.0, 0.0, -10.0))
    c = Checker(g, env)
    g.set_position_target((0.0, 0.0, -10.0), end_speed=2.0)
    while not g.at_target:
        c.step()
        assert c.steps < 10000
    assert g.p[0] == pytest.approx(0.0, abs=0.03) and g.v[0] == pytest.approx(2.0, abs=1e-6)
    c.step(100)  # keeps the end velocity until the next target
    assert g.v[0] == pytest.approx(2.0, abs=1e-6) and g.mode == "velocity"
    c.assert_inside()


def test_yaw_shortest_way_and_continuity() -> None:
    env = make_env("box")
    g = SetpointGenerator(env, 0.01)
    g.reset((0.0, 0.0, -10.0), yaw=math.radians(170.0))
    c = Checker(g, env)
    g.set_yaw_target(math.radians(-170.0))  # 20 degrees the short way, through +-180
    yaws = []
    while not g.yaw_at_target:
        c.step()
        yaws.append(g.yaw)
        assert c.steps < 1000
    assert g.yaw == pytest.approx(wrap(math.radians(-170.0)))
    assert all(abs(y) >= math.radians(170.0) - 1e-9 for y in yaws)  # never went through 0
    g.set_yaw_target(0.0, rate=0.0)  # 0 = the default rate (MAV_CMD_CONDITION_YAW)
    c.step(10)
    assert not g.yaw_at_target
    # rate-limited by the requested rate
    g.set_yaw_target(math.radians(10.0), rate=math.radians(30.0))
    c.step(300)
    assert abs(g.yaw_rate) <= math.radians(30.0) + 1e-12
    assert max(abs(r) for r in [g.yaw_rate]) > 0
    # yaw rate target, then reversal: continuous rate
    g.set_yaw_rate_target(10.0)  # absurd: clipped
    c.step(300)
    assert g.yaw_rate == pytest.approx(env.max_yaw_rate)
    g.set_yaw_rate_target(-1.0)
    c.step(300)
    assert g.yaw_rate == pytest.approx(-1.0)
    g.hold()
    c.step(300)
    assert g.yaw_rate == 0.0
    c.assert_inside()


def test_reset_and_envelope_validation() -> None:
    env = make_env("box")
    g = SetpointGenerator(env, 0.01)
    g.reset((1.0, 2.0, -3.0), (1.0, 0.0, 0.0), 0.5)
    assert g.p == (1.0, 2.0, -3.0) and g.v == (1.0, 0.0, 0.0) and g.yaw == 0.5 and g.mode == "hold"
    with pytest.raises(ValueError):
        g.reset((0.0, 0.0))
    assert g.p == (1.0, 2.0, -3.0)
    with pytest.raises(ValueError):
        Envelope(box=(1.0, 0.0, -1.0, 1.0))
    with pytest.raises(ValueError):
        Envelope(polygon=[(0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0)])  # self-intersecting
    with pytest.raises(ValueError):
        Envelope(alt_floor=10.0, alt_ceiling=5.0)
    with pytest.raises(ValueError):
        Envelope(max_speed_h=0.0)
    assert Polygon(L_SHAPE).is_valid


def test_reset_below_floor_climbs_back() -> None:
    """P_d reset outside P_env (on the ground below the floor) returns inside without jumping."""
    env = make_env("box")
    g = SetpointGenerator(env, 0.01)
    g.reset((0.0, 0.0, 0.0))
    c = Checker(g, env)
    fly_to(g, c, (0.0, 0.0, -10.0), 30.0)
    assert g.p == (0.0, 0.0, -10.0)
