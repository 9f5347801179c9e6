"""Physics of the world: ground contact, motor lag, hover equilibrium, drag, wind."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot_model.airframe import load_airframe
from autopilot_model.physics.quadrotor import PZ, VZ, Quadrotor
from autopilot_model.physics.wind import Wind

DT = 0.002


@pytest.fixture()
def quad() -> Quadrotor:
    af = load_airframe()
    return Quadrotor(af.mass, af.inertia, af.arm_length, af.k_t, af.k_q, af.motor_tau, af.max_speed,
                     af.drag_linear, af.drag_quadratic, af.drag_rotational)


def test_rests_on_ground_without_sinking(quad: Quadrotor) -> None:
    for _ in range(5000):
        quad.step(DT)
    assert quad.position == (0.0, 0.0, 0.0)
    assert quad.velocity == (0.0, 0.0, 0.0)
    assert quad.on_ground
    # the accelerometer at rest measures gravity, upwards in the body frame
    assert quad.out[2] == pytest.approx(-9.80665, abs=1e-6)


def test_drop_lands_without_bounce(quad: Quadrotor) -> None:
    quad.place(down=-5.0)
    touched = None
    for i in range(3000):
        quad.step(DT)
        if quad.on_ground and touched is None:
            touched = i
        if touched is not None:
            assert quad.x[PZ] == 0.0, "sank or bounced after touching down"
            assert quad.x[VZ] == 0.0
    assert touched is not None
    # free fall from 5 m takes about sqrt(2 h / g) (drag slows it a little)
    assert touched * DT == pytest.approx(math.sqrt(2 * 5.0 / 9.80665), rel=0.1)


def test_motor_first_order_lag(quad: Quadrotor) -> None:
    quad.cmd[:] = 1.0
    tau = quad.prm[6]
    n = round(tau / DT)
    for _ in range(n):
        quad.step(DT)
    frac = quad.w_mot[0] / quad.prm[7]
    assert frac == pytest.approx(1 - math.exp(-1), abs=0.05)


def test_hover_command_balances_weight(quad: Quadrotor) -> None:
    quad.place(down=-10.0)
    quad.cmd[:] = quad.hover_command
    quad.w_mot[:] = math.sqrt(quad.hover_command) * quad.prm[7]
    for _ in range(500):
        quad.step(DT)
    assert abs(quad.velocity[2]) < 1e-6
    assert quad.position[2] == pytest.approx(-10.0, abs=1e-6)


def test_differential_thrust_rolls_right(quad: Quadrotor) -> None:
    """Left motors (3 front-left, 2 back-left) faster than right ones: positive roll (right wing down)."""
    quad.place(down=-10.0)
    c = quad.hover_command
    quad.cmd[:] = (c - 0.05, c + 0.05, c + 0.05, c - 0.05)
    for _ in range(100):
        quad.step(DT)
    assert quad.rates[0] > 0.1
    assert abs(quad.rates[1]) < 1e-6


def test_drag_opposes_air_relative_velocity(quad: Quadrotor) -> None:
    quad.place(down=-50.0)
    quad.x[3] = 10.0  # 10 m/s north, motors off
    quad.step(DT)
    assert quad.out[4] < 0.0  # decelerating north
    still = Quadrotor(1.5, (0.015, 0.015, 0.027), 0.25, 7.5e-6, 1.2e-7, 0.02, 1000, 0.1, 0.05, 0.002)
    still.place(down=-50.0)
    still.wind[:] = (10.0, 0.0, 0.0)
    still.step(DT)
    assert still.out[4] == pytest.approx(-quad.out[4], rel=1e-6)  # wind pushes like the opposite motion


def test_wind_gusts_bounded_with_requested_spread() -> None:
    w = Wind((1.0, 0.0, 0.0), gust_sigma=0.5, gust_max=1.0, tau_s=1.0, seed=3)
    out = np.zeros(3)
    samples = []
    for _ in range(50000):
        w.step(DT, out)
        samples.append(out.copy())
    s = np.array(samples)
    assert np.all(np.abs(s[:, 0] - 1.0) <= 1.0 + 1e-12)
    assert s[:, 0].mean() == pytest.approx(1.0, abs=0.2)
    assert 0.25 < s[:, 1].std() < 0.6
