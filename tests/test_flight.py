"""Closed-loop flights of the model on its Python API.

Hover, a climb to 10 m, a 50 m square at 5 m/s and a landing, with the estimator (not the truth) in the
loop, sensor noise and gusts on; disarmed, the vehicle rests on the ground.
"""

from __future__ import annotations

import math

import pytest

from autopilot_model.airframe import load_airframe
from autopilot_model.flights import goto, land, takeoff
from autopilot_model.modules.navigation import LANDED_ON_GROUND
from autopilot_model.vehicle import Vehicle
from harness.square import fly_and_check_square


def _vehicle(profile: str = "indoor", gusts: bool = True, seed: int = 1) -> Vehicle:
    af = load_airframe()
    if gusts:
        af.gust_sigma, af.gust_max = 0.5, 1.0
    return Vehicle(af, sensors=profile, seed=seed)


def test_disarmed_vehicle_rests_on_ground() -> None:
    v = _vehicle()
    v.run_for(5.0)
    assert v.world.position == (0.0, 0.0, 0.0)
    assert not v.nav.armed
    assert v.nav.landed_state == LANDED_ON_GROUND
    assert all(c == 0.0 for c in v.world.cmd)


def test_arm_refused_before_estimator_ready() -> None:
    v = _vehicle()
    ok, reason = v.nav.arm()
    assert not ok and "EKF" in reason
    assert not v.nav.armed


def test_hover_climb_and_hold() -> None:
    v = _vehicle()
    takeoff(v, 10.0)
    v.run_for(10.0)
    n, e, d = v.world.position
    assert d == pytest.approx(-10.0, abs=0.1)
    assert math.hypot(n, e) < 0.1
    # the estimate is not the truth passed through, but close to it
    est = v.state.position_ned
    assert est != v.world.position
    assert math.dist(est, v.world.position) < 0.05
    assert abs(v.world.velocity[2]) < 0.1


def test_square_and_landing_track_setpoints() -> None:
    fly_and_check_square(_vehicle())


def test_outdoor_gps_flight_does_not_diverge() -> None:
    af = load_airframe()
    af.gust_sigma, af.gust_max, af.wind_mean = 1.5, 3.0, (3.0, 2.0, 0.0)
    v = Vehicle(af, sensors="outdoor", seed=2)
    takeoff(v, 10.0)
    goto(v, (30.0, -20.0, -15.0), 8.0)
    v.run_for(5.0)
    assert math.dist(v.world.position, (30.0, -20.0, -15.0)) < 3.0  # GPS-grade error
    land(v)
    assert not v.nav.armed


def test_goto_on_ground_is_refused() -> None:
    v = _vehicle()
    v.wait_estimator()
    v.nav.arm()
    ok, reason = v.nav.goto((10.0, 0.0, -5.0))
    assert not ok and "take off first" in reason


def test_takeoff_superseded_by_a_target_reports_in_air() -> None:
    v = _vehicle(gusts=False)
    v.wait_estimator()
    v.nav.arm()
    v.nav.takeoff(10.0)
    v.run_for(2.0)
    assert v.nav.landed_state == 3  # MAV_LANDED_STATE_TAKEOFF
    ok, _ = v.nav.goto((5.0, 0.0, -4.0), 2.0)
    assert ok
    assert v.run_until(lambda: v.nav.landed_state == 2, 10.0)  # MAV_LANDED_STATE_IN_AIR
