"""The module resolver chooses the position source and sets its rate (seed 002 Sec. 3.2).

``gps`` and ``mocap`` both provide ``@position_source`` and conflict (Fig. 3); the sensor profile is a
module of the library that depends on one of them, so the resolver (Algorithms 1-2), not the vehicle's
code, loads the source. Its sensor function runs at the frequency the module library gives it (its
prescaler in the static schedule), and the sample period the sensor and the estimator use is that step.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from autopilot_model.airframe import load_airframe
from autopilot_model.flights import takeoff
from autopilot_model.scheduler import SchedulerError
from autopilot_model.vehicle import DEFAULT_MODULES, Vehicle


def _count_sensor_calls(v: Vehicle, iterations: int) -> int:
    """Calls of the position sensor over ``iterations`` main-loop iterations (started at iteration 0)."""
    gps = v.gps
    original = gps.periodic
    calls = [0]

    def counted(now: float) -> None:
        calls[0] += 1
        original(now)

    gps.periodic = counted  # type: ignore[method-assign]
    try:
        v.step(iterations)
    finally:
        del gps.periodic
    return calls[0]


def _library_with(tmp_path: Path, pattern: str, replacement: str) -> Path:
    text, n = re.subn(pattern, replacement, DEFAULT_MODULES.read_text(encoding="utf-8"))
    assert n == 1, pattern
    path = tmp_path / "modules.yaml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(("profile", "source", "hz"), [("outdoor", "gps", 10), ("perfect", "gps", 10),
                                                       ("indoor", "mocap", 100)])
def test_the_profile_selects_its_source_through_the_resolver(profile: str, source: str, hz: int) -> None:
    v = Vehicle(load_airframe(), sensors=profile, seed=1)
    loop = v.start()
    sched = loop.schedule
    assert v.position_source == source and v.estimator.position_source == source
    assert sched.resolution.provided["@position_source"] == (source,)
    other = "mocap" if source == "gps" else "gps"
    assert source in sched.modules and other not in sched.modules
    assert v.gps.is_gps == (source == "gps")
    (fn,) = [p for p in sched.periodic if p.module == source]
    assert fn.name == f"{source}.periodic" and fn.freq == hz and fn.prescaler == 500 // hz
    # the sensor is called exactly at the schedule's rate: N iterations -> N / prescaler calls
    n = 20 * fn.prescaler
    assert _count_sensor_calls(v, n) == 20
    assert v.gps.dt == pytest.approx(1.0 / hz) == v.estimator.pos_dt == v.step_of(fn.name)


@pytest.mark.parametrize(("profile", "function", "old", "new"), [("outdoor", "gps.periodic", 10, 5),
                                                                 ("indoor", "mocap.periodic", 100, 50)])
def test_a_rate_changed_in_the_library_changes_the_call_rate(tmp_path: Path, profile: str, function: str,
                                                             old: int, new: int) -> None:
    library = _library_with(tmp_path, rf"\{{function: {re.escape(function)}, freq: {old}\}}",
                            f"{{function: {function}, freq: {new}}}")
    v = Vehicle(load_airframe(), modules_file=library, sensors=profile, seed=1)
    iterations = 2 * 500  # 2 s at 500 Hz
    assert _count_sensor_calls(v, iterations) == 2 * new
    assert v.gps.dt == pytest.approx(1.0 / new) == v.estimator.pos_dt


def test_a_5_hz_gps_from_the_library_still_flies(tmp_path: Path) -> None:
    """The estimator's position observer takes its sample period from the schedule: at 5 Hz the
    vehicle takes off and hovers where it should."""
    library = _library_with(tmp_path, r"\{function: gps\.periodic, freq: 10\}",
                            "{function: gps.periodic, freq: 5}")
    v = Vehicle(load_airframe(), modules_file=library, sensors="outdoor", seed=2)
    takeoff(v, 10.0)
    v.run_for(10.0)
    n, e, d = v.world.position
    assert abs(-d - 10.0) < 2.0 and (n * n + e * e) ** 0.5 < 3.0
    assert v.estimator.rejected == 0


@pytest.mark.parametrize(("profile", "extra"), [("indoor", "gps"), ("outdoor", "mocap")])
def test_gps_and_mocap_together_are_refused(profile: str, extra: str) -> None:
    v = Vehicle(load_airframe(), sensors=profile, seed=1, extra_select=[extra])
    with pytest.raises(SchedulerError, match=r"conflict: module '(gps|mocap)' .* conflicts with module "
                                             r"'(gps|mocap)'.*both are loaded"):
        v.start()
    assert v.loop is None  # nothing built, nothing run


def test_a_library_that_selects_gps_conflicts_with_an_indoor_profile(tmp_path: Path) -> None:
    """The source is never swapped by code: a library whose selection names ``gps`` cannot fly the
    motion-capture profile."""
    library = _library_with(tmp_path, r"select: \[imu, ", "select: [imu, gps, ")
    v = Vehicle(load_airframe(), modules_file=library, sensors="indoor", seed=1)
    with pytest.raises(SchedulerError, match="conflict"):
        v.start()
    ok = Vehicle(load_airframe(), modules_file=library, sensors="outdoor", seed=1)
    assert ok.position_source == "gps"


def test_a_profile_missing_from_the_library_is_a_clear_error(tmp_path: Path) -> None:
    library = _library_with(tmp_path, r"  - name: indoor\n", "  - name: indoor_lab\n")
    v = Vehicle(load_airframe(), modules_file=library, sensors="indoor", seed=1)
    with pytest.raises(SchedulerError, match=r"selected module.*not in the library: indoor"):
        v.start()


def test_two_position_sources_without_a_conflict_declared_are_refused(tmp_path: Path) -> None:
    """A library that forgets the conflict still cannot fly two position sources: the vehicle checks
    that exactly one module provides ``@position_source`` before it changes anything."""
    text = DEFAULT_MODULES.read_text(encoding="utf-8")
    text, n = re.subn(r"(?m)^    conflicts: (gps|mocap)\n", "", text)
    assert n == 2
    library = tmp_path / "modules.yaml"
    library.write_text(text, encoding="utf-8")
    v = Vehicle(load_airframe(), modules_file=library, sensors="outdoor", seed=1, extra_select=["mocap"])
    dt = v.estimator.dt
    with pytest.raises(SchedulerError, match=r"exactly one module must provide '@position_source'.*2: "):
        v.start()
    assert v.loop is None and v.steps == {} and v.estimator.dt == dt and v.gps.module == ""
