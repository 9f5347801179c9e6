"""Reference generation (seed 000 Sec. IV-D, Fig. 9): exact arrival, straight lines, bounds, envelope."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.flight import Envelope
from companion.flight.reference import (
    HOLD,
    AxisTarget,
    ChannelTargets,
    PathTarget,
    Reference,
    ReferenceGenerator,
    StepResult,
    VelocityTarget,
    YawRateTarget,
    YawTarget,
    wrap_pi,
)
from harness.flight_sim import LIMITS

DT = 0.02


def _rest(p=(0.0, 0.0, -5.0), yaw=0.0) -> Reference:
    return Reference(0.0, p, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), yaw)


def _check_step(r0: Reference, r1: Reference, dt: float = DT) -> None:
    L = LIMITS
    tol = 1e-9
    assert math.hypot(r1.v[0] - r0.v[0], r1.v[1] - r0.v[1]) <= L.horizontal_acceleration * dt + tol
    assert abs(r1.v[2] - r0.v[2]) <= L.vertical_acceleration * dt + tol
    assert math.hypot(r1.p[0] - r0.p[0], r1.p[1] - r0.p[1]) <= L.horizontal_speed * dt + tol
    assert abs(r1.p[2] - r0.p[2]) <= L.vertical_speed * dt + tol
    assert abs(r1.yaw - r0.yaw) <= math.radians(L.yaw_rate) * dt + tol


def _fly(
    gen: ReferenceGenerator, ref: Reference, targets: ChannelTargets, until, max_s: float = 60.0
) -> tuple[Reference, list[StepResult]]:
    results: list[StepResult] = []
    for _ in range(int(max_s / DT)):
        res = gen.step(ref, targets, DT)
        _check_step(ref, res.reference)
        results.append(res)
        ref = res.reference
        if until(res):
            return ref, results
    raise AssertionError("did not arrive")


def test_straight_line_from_rest_arrives_exactly_at_commanded_speed() -> None:
    gen = ReferenceGenerator(LIMITS)
    targets = ChannelTargets(PathTarget((30.0, 40.0), speed=4.0), AxisTarget(-5.0, 2.0), YawRateTarget(0.0))
    ref, results = _fly(gen, _rest(), targets, lambda r: r.h_arrived)
    assert ref.p == (30.0, 40.0, -5.0) and ref.v == (0.0, 0.0, 0.0)
    speeds = [math.hypot(*r.reference.v[:2]) for r in results]
    assert max(speeds) == pytest.approx(4.0, abs=1e-9)
    for r in results:  # on the line 3:4 through the origin
        n, e = r.reference.p[:2]
        assert abs(4 * n - 3 * e) / 5 < 1e-9
    assert gen.guard_interventions == 0


def test_3d_line_arrives_exactly_with_end_speed_and_slows_for_the_vertical_limit() -> None:
    gen = ReferenceGenerator(LIMITS)
    end_v = (0.0, 1.0, -0.5)  # along the line (0, 10, -5): horizontal end speed 1
    targets = ChannelTargets(
        PathTarget((0.0, 10.0, -10.0), speed=5.0, end_velocity=end_v), None, YawRateTarget(0.0)
    )
    ref, results = _fly(gen, _rest(), targets, lambda r: r.h_arrived)
    assert ref.p == (0.0, 10.0, -10.0) and ref.v == end_v
    assert max(abs(r.reference.v[2]) for r in results) == pytest.approx(2.0, abs=1e-6)  # vertical limit bound
    assert all(abs(r.reference.p[0]) < 1e-9 for r in results)
    assert all(abs(r.reference.p[1] / 2 + r.reference.p[2] + 5) < 1e-9 for r in results)


def test_new_target_while_moving_sideways_is_continuous_and_exact() -> None:
    gen = ReferenceGenerator(LIMITS)
    moving = Reference(0.0, (0.0, 0.0, -5.0), (0.0, 4.0, 0.0), (0.0, 1.0, 0.0), 0.0)
    targets = ChannelTargets(PathTarget((20.0, 0.0), speed=3.0), AxisTarget(-5.0, 2.0), YawRateTarget(0.0))
    ref, _ = _fly(gen, moving, targets, lambda r: r.h_arrived)
    assert ref.p == (20.0, 0.0, -5.0)


def test_speed_modifier_makes_channels_arrive_together() -> None:
    gen = ReferenceGenerator(LIMITS)
    targets = ChannelTargets(
        PathTarget((5.0, 0.0), speed=5.0), AxisTarget(-15.0, 2.0), YawRateTarget(0.0), h_sync_vertical=True
    )
    _, results = _fly(gen, _rest(), targets, lambda r: r.h_arrived and r.v_arrived)
    first_h = next(i for i, r in enumerate(results) if r.h_arrived)
    first_v = next(i for i, r in enumerate(results) if r.v_arrived)
    assert first_h == first_v
    # without the modifier the horizontal is much earlier
    _, results = _fly(
        ReferenceGenerator(LIMITS),
        _rest(),
        ChannelTargets(PathTarget((5.0, 0.0), speed=5.0), AxisTarget(-15.0, 2.0), YawRateTarget(0.0)),
        lambda r: r.v_arrived,
    )
    assert next(i for i, r in enumerate(results) if r.h_arrived) < first_v - 50


def test_yaw_goes_the_long_way_when_the_unwrapped_target_says_so() -> None:
    gen = ReferenceGenerator(LIMITS)
    target = -math.radians(270)  # from 0, turning negative to +90 deg
    ref, results = _fly(
        gen,
        _rest(),
        ChannelTargets(VelocityTarget((0, 0)), VelocityTarget((0,)), YawTarget(target, math.radians(60))),
        lambda r: r.hd_arrived,
    )
    assert ref.yaw == target and wrap_pi(ref.yaw) == pytest.approx(math.radians(90))
    assert all(r.reference.yaw_rate <= 1e-12 for r in results)


def test_hold_brakes_smoothly_and_stays() -> None:
    gen = ReferenceGenerator(LIMITS)
    ref = Reference(0.0, (0.0, 0.0, -5.0), (3.0, -2.0, 1.0), (0.0, 0.0, 0.0), 0.0, 0.5)
    for _ in range(300):
        new = gen.step(ref, HOLD, DT).reference
        _check_step(ref, new)
        ref = new
    assert ref.v == (0.0, 0.0, 0.0) and ref.yaw_rate == 0.0
    assert gen.step(ref, HOLD, DT).reference.p == ref.p


def test_velocity_into_the_envelope_wall_stops_inside() -> None:
    env = Envelope.box(-10, 10, -10, 10, altitude_floor=1.0, altitude_ceiling=8.0)
    gen = ReferenceGenerator(LIMITS, env)
    ref = _rest((0.0, 0.0, -5.0))
    flags = []
    targets = ChannelTargets(VelocityTarget((5.0, 3.0)), VelocityTarget((-2.0,)), YawRateTarget(0.0))
    for _ in range(1000):
        res = gen.step(ref, targets, DT)
        _check_step(ref, res.reference)
        ref = res.reference
        flags.append(res.limit_reached)
        assert env.contains(np.array(ref.p))
    assert any(flags) and flags[-1]
    assert ref.p[0] > 9.0 and ref.p[1] > 9.0 and -ref.p[2] > 7.5  # slid into the corner, below the ceiling


def test_position_target_outside_is_unreachable_and_held_on_the_boundary() -> None:
    env = Envelope([(-10, -10), (10, -10), (10, 10), (-10, 10)])
    gen = ReferenceGenerator(LIMITS, env)
    targets = ChannelTargets(PathTarget((30.0, 0.0), speed=5.0), AxisTarget(-5.0, 2.0), YawRateTarget(0.0))
    ref, results = _fly(gen, _rest(), targets, lambda r: r.h_arrived)
    assert all(r.target_unreachable for r in results)
    assert ref.p[:2] == pytest.approx((10.0, 0.0))
