"""The estimator's divergence and consistency checks and ArduCopter's EKF failsafe.

A non-finite estimate or persistently rejected position samples make the estimate unhealthy; the
failsafe (ArduCopter ``Copter::ekf_check`` at 10 Hz, 1 s of bad variance) announces "EKF variance",
clears the AHRS health bit and switches to LAND (FS_EKF_ACTION 1). No NaN reaches the state interface
or telemetry. The vehicle runs in-process on its Python API (same seed: deterministic).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest
from pymavlink.dialects.v20 import common as mavlink

from autopilot_model.modules.flight_modes import GUIDED, LAND
from autopilot_model.modules.navigation import LANDED_ON_GROUND
from autopilot_model.sitl import Sitl

pytestmark = pytest.mark.integration

NAN = math.nan


SITL_TAKEOFF_M = 10.0  # the sitl fixture: each test starts hovering in GUIDED at 10 m


def _published_finite(s: Sitl) -> bool:
    """What the state interface and the telemetry carry is finite."""
    st = s.vehicle.state
    att = s.link.telemetry.attitude()
    values = [*st.position_ned, *st.velocity_ned, *st.quat, *st.body_rates,
              att.roll, att.pitch, att.yaw, att.rollspeed, att.pitchspeed, att.yawspeed]
    lpos = s.link.telemetry.local_position_ned()
    values += [lpos.x, lpos.y, lpos.z, lpos.vx, lpos.vy, lpos.vz]
    return all(math.isfinite(x) for x in values)


def _run(s: Sitl, seconds: float, each: Callable[[], None] | None = None) -> bool:
    """Run ``seconds`` of simulated time in 10 ms steps; returns whether every published value was
    finite after every step."""
    v = s.vehicle
    finite = True
    end = v.clock.now() + seconds
    while v.clock.now() < end:
        if each is not None:
            each()
        v.step(5)
        finite = finite and _published_finite(s)
    return finite


def _ahrs_healthy(s: Sitl) -> bool:
    return bool(s.link.telemetry.sys_status().onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_AHRS)


def _wild_position(s: Sitl, offset: tuple[float, float, float], samples: int | None) -> None:
    """Add ``offset`` to the next ``samples`` position samples (None: to all of them)."""
    gps = s.vehicle.gps
    original = gps.periodic
    left = [samples]

    def periodic(now: float) -> None:
        original(now)
        if gps.fresh and gps.sample is not None and (left[0] is None or left[0] > 0):
            gps.sample = tuple(x + d for x, d in zip(gps.sample, (*offset, 0.0, 0.0, 0.0), strict=True))
            if left[0] is not None:
                left[0] -= 1

    gps.periodic = periodic  # type: ignore[method-assign]


def test_nan_in_the_estimate_triggers_the_ekf_failsafe(sitl: Sitl) -> None:
    v = sitl.vehicle
    assert _ahrs_healthy(sitl) and sitl.modes.mode == GUIDED
    v.estimator.est[0] = NAN  # a diverged estimate
    finite = _run(sitl, 0.5)
    assert finite, "a NaN estimate reached the state interface or the telemetry"
    assert not _ahrs_healthy(sitl)
    assert _run(sitl, 2.0)
    assert sitl.modes.mode == LAND
    assert "EKF variance" in sitl.safety.events
    assert sitl.safety.ekf_failsafe and sitl.link.telemetry.system_status() == mavlink.MAV_STATE_CRITICAL
    # it lands on the restored estimate and disarms; the failsafe clears once disarmed
    assert v.run_until(lambda: not v.nav.armed, 40.0)
    assert v.nav.landed_state == LANDED_ON_GROUND and math.hypot(*v.world.position[:2]) < 3.0
    v.run_for(0.5)
    assert not sitl.safety.ekf_failsafe


def test_nan_position_samples_are_rejected_and_trigger_the_failsafe(sitl: Sitl) -> None:
    v = sitl.vehicle
    gps = v.gps
    original = gps.periodic

    def nan_samples(now: float) -> None:
        original(now)
        if gps.fresh:
            gps.sample = (NAN, 0.0, -10.0, 0.0, 0.0, 0.0)

    gps.periodic = nan_samples  # type: ignore[method-assign]
    assert _run(sitl, 3.0)
    assert sitl.modes.mode == LAND and "EKF variance" in sitl.safety.events
    assert math.dist(v.state.position_ned, v.world.position) < 2.0


def test_a_wild_position_glitch_is_rejected(sitl: Sitl) -> None:
    v = sitl.vehicle
    _wild_position(sitl, (50.0, 0.0, 0.0), samples=3)  # 0.3 s of a 50 m GPS glitch
    worst = 0.0

    def track() -> None:
        nonlocal worst
        worst = max(worst, math.dist(v.state.position_ned, v.world.position))

    assert _run(sitl, 3.0, track)
    assert worst < 1.5, f"the estimate followed the glitch ({worst:.1f} m)"
    assert sitl.modes.mode == GUIDED and not sitl.safety.ekf_failsafe
    assert _ahrs_healthy(sitl)
    assert math.hypot(*v.world.position[:2]) < 2.0


def test_a_persistent_wild_position_triggers_the_failsafe(sitl: Sitl) -> None:
    v = sitl.vehicle
    _wild_position(sitl, (0.0, 80.0, 0.0), samples=None)
    assert _run(sitl, 0.5)
    assert not _ahrs_healthy(sitl)
    assert _run(sitl, 2.0)
    assert sitl.modes.mode == LAND and "EKF variance" in sitl.safety.events
    assert math.dist(v.state.position_ned, v.world.position) < 3.0  # the wild samples never fused


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_the_finite_check_fires_outside_fastmath(bad: float) -> None:
    """The check is compiled without fastmath, so NaN and infinity are seen; ``good`` keeps the last
    finite state."""
    import numpy as np

    from autopilot_model.modules.estimation import ins_state_finite

    est, acc, gbias, abias, good = np.arange(13.0), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(13)
    assert ins_state_finite(est, acc, gbias, abias, good) and list(good) == list(est)
    est[5] = bad
    assert not ins_state_finite(est, acc, gbias, abias, good) and good[5] == 5.0
    est[5] = 5.0
    abias[1] = bad
    assert not ins_state_finite(est, acc, gbias, abias, good)
