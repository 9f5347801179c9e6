"""Every step follows the schedule's main loop rate.

The physics, the estimator, the setpoint generator, the controller and the navigator take their step
from the schedule (main loop period times the function's prescaler), and the simulated clock advances by
the same period: the 50 m square flies the same at 400, 500 and 1000 Hz, with the 500 Hz functions at
the main loop rate or, at 1000 Hz, every second iteration.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from autopilot_model.airframe import load_airframe
from autopilot_model.vehicle import DEFAULT_MODULES, Vehicle
from harness.square import fly_and_check_square


def _modules_at(tmp_path: Path, main_hz: int, fast_hz: int) -> Path:
    """The bundled module library, main loop at ``main_hz``, its 500 Hz functions at ``fast_hz``."""
    text = DEFAULT_MODULES.read_text(encoding="utf-8")
    text, n = re.subn(r"(?m)^main_loop_hz: 500$", f"main_loop_hz: {main_hz}", text)
    assert n == 1
    text, n = re.subn(r"freq: 500\}", f"freq: {fast_hz}}}", text)
    assert n >= 5
    path = tmp_path / f"modules_{main_hz}_{fast_hz}.yaml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(("main_hz", "fast_hz"), [(400, 400), (500, 500), (1000, 500), (1000, 1000)])
def test_square_flies_the_same_at_every_loop_rate(tmp_path: Path, main_hz: int, fast_hz: int) -> None:
    af = load_airframe()
    af.gust_sigma, af.gust_max = 0.5, 1.0
    v = Vehicle(af, modules_file=_modules_at(tmp_path, main_hz, fast_hz), sensors="indoor", seed=1)
    loop = v.start()
    assert loop.schedule.main_loop_hz == main_hz
    fly_and_check_square(v)  # the bounds of the 500 Hz flight (tests/test_flight.py)
    # simulated time = scheduled iterations x period, for the clock and for the physics alike
    assert loop.period_us == 1_000_000 // main_hz
    assert v.clock.now_us == loop.iteration * loop.period_us
    assert v.world.time_s == pytest.approx(v.clock.now(), rel=1e-9)


def test_every_step_is_the_period_times_the_prescaler(tmp_path: Path) -> None:
    """At 1000 Hz with the 500 Hz functions every second iteration and the navigator at 50 Hz."""
    v = Vehicle(load_airframe(), modules_file=_modules_at(tmp_path, 1000, 500), sensors="perfect", seed=1)
    loop = v.start()
    prescaler = {p.name: p.prescaler for p in loop.schedule.periodic}
    assert prescaler["ins.periodic"] == 2 and prescaler["nav.periodic"] == 20
    period = loop.period_us / 1e6
    assert v.dt == pytest.approx(0.001)  # the physics step
    assert v.estimator.dt == pytest.approx(2 * period)
    assert v.guidance.dt == pytest.approx(2 * period)
    assert v.control.dt == pytest.approx(2 * period)
    assert v.nav_dt == pytest.approx(20 * period)
    v.run_for(1.0)
    assert v.clock.now_us == 1_000_000 == loop.iteration * loop.period_us
    assert v.world.time_s == pytest.approx(1.0, rel=1e-9)
