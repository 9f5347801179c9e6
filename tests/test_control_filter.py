"""The horizontal velocity error filter (PSC_VELXY_FLTE / PSC_VELXY_FLTD).

Held against a plain transcription of ArduPilot's ``AC_PID_2D::update_all`` (error low-pass with
``calc_lowpass_alpha_dt``, derivative of the filtered error low-passed again, a reset that starts the
filter at the raw error with a zero derivative), and judged in flight by what the vehicle does.
"""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from autopilot_model.airframe import load_airframe
from autopilot_model.flights import takeoff
from autopilot_model.modules.control import CascadedController
from autopilot_model.params import ParamStore
from autopilot_model.physics.quadrotor import VX, VY
from autopilot_model.vehicle import Vehicle

DT = 0.002


def _alpha(dt: float, hz: float) -> float:
    """ArduPilot's calc_lowpass_alpha_dt."""
    return 1.0 if hz == 0.0 else dt / (dt + 1.0 / (2.0 * math.pi * hz))


class ArduPid2D:
    """AC_PID_2D::update_all without I and FF (P on the filtered error, D on its filtered derivative)."""

    def __init__(self, kp: float, kd: float, flte: float, fltd: float) -> None:
        self.kp, self.kd, self.flte, self.fltd = kp, kd, flte, fltd
        self.reset = True
        self.err = np.zeros(2)
        self.deriv = np.zeros(2)

    def update(self, target: np.ndarray, measurement: np.ndarray, dt: float) -> np.ndarray:
        if self.reset:
            self.reset = False
            self.err = target - measurement
            self.deriv = np.zeros(2)
        else:
            last = self.err.copy()
            self.err = self.err + ((target - measurement) - self.err) * _alpha(dt, self.flte)
            self.deriv = self.deriv + ((self.err - last) / dt - self.deriv) * _alpha(dt, self.fltd)
        return self.err * self.kp + self.deriv * self.kd


def _controller(**params: float) -> CascadedController:
    store = ParamStore()
    c = CascadedController(store, 1.5, (0.03, 0.03, 0.05), 4 * 9.0, DT)
    for name, value in {"PSC_VELXY_I": 0.0, "PSC_POSXY_P": 0.0, **params}.items():
        store.set(name, value)
    return c


@pytest.mark.parametrize(("flte", "fltd"), [(5.0, 5.0), (0.0, 0.0), (2.0, 20.0)])
def test_velocity_loop_filters_as_ac_pid_2d(flte: float, fltd: float) -> None:
    kp, kd = 6.0, 0.25
    c = _controller(PSC_VELXY_P=kp, PSC_VELXY_D=kd, PSC_VELXY_FLTE=flte, PSC_VELXY_FLTD=fltd)
    ref_pid = ArduPid2D(kp, kd, flte, fltd)
    rng = random.Random(1)
    est = np.zeros(13)
    est[6] = 1.0  # level, at rest
    target = np.zeros(2)
    for k in range(400):
        if k == 200:  # a reset (arming, disarmed) restarts the filter as ArduPilot's reset_filter
            c.reset()
            ref_pid.reset = True
        # random walks (unfiltered, the derivative of white noise would saturate the tilt)
        target = target + np.array([rng.gauss(0.0, 0.003), rng.gauss(0.0, 0.003)])
        est[3] += rng.gauss(0.0, 0.003)
        est[4] += rng.gauss(0.0, 0.003)
        c.step(est, (0.0, 0.0, 0.0), (target[0], target[1], 0.0), (0.0, 0.0, 0.0), 0.0, 0.0)
        want = ref_pid.update(target, est[3:5], DT)
        assert c.out[11] == 0.0  # not saturated: a_cmd is the PID's output
        assert c.out[8] == pytest.approx(want[0], rel=1e-9, abs=1e-9)  # a_cmd north
        assert c.out[9] == pytest.approx(want[1], rel=1e-9, abs=1e-9)  # a_cmd east


@pytest.mark.integration
def test_defaults_are_arducopters_and_a_change_takes_effect_in_flight() -> None:
    store = ParamStore()
    c = CascadedController(store, 1.5, (0.03, 0.03, 0.05), 4 * 9.0, DT)
    assert store.get("PSC_VELXY_FLTE") == 5.0  # POSCONTROL_VEL_XY_FILT_HZ
    assert store.get("PSC_VELXY_FLTD") == 5.0  # POSCONTROL_VEL_XY_FILT_D_HZ
    assert c is not None

    def hover_speed_median(params: dict[str, float]) -> float:
        v = Vehicle(load_airframe(), sensors="outdoor", seed=3)
        takeoff(v, 10.0)
        for name, value in params.items():  # set in flight, as a ground station would
            v.params.set(name, value)
        v.run_for(2.0)
        speeds = []
        for _ in range(500):
            v.run_for(0.02)
            speeds.append(math.hypot(v.world.x[VX], v.world.x[VY]))
        return float(np.median(speeds))

    off = hover_speed_median({"PSC_VELXY_FLTE": 0.0, "PSC_VELXY_FLTD": 0.0})
    default = hover_speed_median({})
    only_d = hover_speed_median({"PSC_VELXY_D": 0.25, "PSC_VELXY_FLTD": 1.0})
    assert off != default  # FLTE flies
    assert only_d != default  # FLTD flies (through the D term)
