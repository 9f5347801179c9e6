"""The main loop (seed 002 Sec. 4.2, Fig. 4) and its statistics (Sec. 5, Table 2)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from autopilot_model.scheduler import (
    TASK_GROUPS,
    MainLoop,
    SchedulerError,
    build_schedule,
    load_modules,
    parse_modules,
)
from taskflight_common.clock import SimClock

FIXTURES = Path(__file__).parent / "fixtures"

# Listed out of dependency order on purpose (ins before ahrs, ctrl before its inputs).
LIBRARY: dict[str, Any] = {
    "main_loop_hz": 100,
    "modules": [
        {"name": "ctrl", "task_group": "control", "depends": "ins", "init": ["ctrl.init"],
         "periodic": [{"function": "ctrl.run", "freq": 100}]},
        {"name": "ins", "task_group": "estimation", "depends": "ahrs",
         "periodic": [{"function": "ins.update", "freq": 50, "offset": 1}]},
        {"name": "telem", "task_group": "telemetry",
         "periodic": [{"function": "telem.send", "freq": 10, "offset": 7}]},
        {"name": "ahrs", "task_group": "estimation", "depends": "imu", "init": ["ahrs.init"],
         "periodic": [{"function": "ahrs.update", "freq": 100}]},
        {"name": "imu", "task_group": "sensors", "init": ["imu.init"], "event": ["imu.event"],
         "periodic": [{"function": "imu.read", "freq": 100}]},
        {"name": "baro", "task_group": "sensors",
         "periodic": [{"function": "baro.read", "freq": 25, "offset": 3}]},
        {"name": "motors", "task_group": "actuators", "depends": "ctrl",
         "periodic": [{"function": "motors.set", "freq": 100}]},
        {"name": "nav", "task_group": "navigation", "depends": "ins",
         "periodic": [{"function": "nav.run", "freq": 10, "offset": 0}]},
        {"name": "dl", "task_group": "core", "event": ["dl.poll"],
         "periodic": [{"function": "dl.periodic", "freq": 20, "offset": 2}]},
    ],
    "select": ["telem", "ctrl", "motors", "nav", "dl", "baro"],
}


def recording_registry(names: list[str], log: list[str]) -> dict[str, Callable[[], None]]:
    def make(n: str) -> Callable[[], None]:
        return lambda: log.append(n)
    return {n: make(n) for n in names}


def all_function_names(cfg: Any) -> list[str]:
    return [n for m in cfg.modules.values()
            for n in (*m.init, *m.event, *(p.function for p in m.periodic))]


def expected_calls(i: int) -> list[str]:
    """Written from the rules, independently of the implementation."""
    out = ["imu.event", "dl.poll"]                                      # events, every iteration
    out += ["imu.read"] + (["baro.read"] if i % 4 == 3 else [])         # sensors
    out += ["ahrs.update"] + (["ins.update"] if i % 2 == 1 else [])     # estimation (topological)
    out += ["nav.run"] if i % 10 == 0 else []                           # navigation
    out += ["ctrl.run", "motors.set"]                                   # control, actuators
    out += ["dl.periodic"] if i % 5 == 2 else []                        # core
    out += ["telem.send"] if i % 10 == 7 else []                        # telemetry
    return out


@pytest.mark.parametrize("timed", [True, False])
def test_order_prescalers_offsets_events_world_and_clock(timed: bool) -> None:
    cfg = parse_modules(LIBRARY)
    log: list[str] = []
    clock = SimClock(speedup=0)
    world_times: list[int] = []

    def world() -> None:
        log.append("world")
        world_times.append(clock.now_us)

    sch = build_schedule(cfg, recording_registry(all_function_names(cfg), log), heuristic="none")
    assert sch.modules == ("telem", "imu", "ahrs", "ins", "ctrl", "motors", "nav", "dl", "baro")
    assert sch.groups["estimation"] == ("ahrs", "ins")
    loop = MainLoop(sch, clock, world_step=world)
    loop.set_timed(timed)  # untimed (a fleet's vehicle): the same calls in the same order
    loop.run_init()
    assert log == ["imu.init", "ahrs.init", "ctrl.init"]        # topological order
    for i in range(40):
        log.clear()
        loop.step()
        assert log == [*expected_calls(i), "world"], f"iteration {i}"
        assert clock.now_us == (i + 1) * 10_000
    assert world_times == [i * 10_000 for i in range(40)]     # world steps before the clock advances
    assert loop.iteration == 40
    stats = loop.stats.as_dict()
    assert stats["timed"] is timed and stats["iterations"] == 40
    calls = sum(1 for n in (*loop.stats.groups["sensors"].buf, *loop.stats.groups["world"].buf))
    assert (calls > 0) is timed  # untimed: no stamp taken
    assert ("not timed" in loop.stats.table()) is not timed


def test_optimised_offsets_run_at_their_phase() -> None:
    data = {**LIBRARY, "modules": [
        {**m, "periodic": [{k: v for k, v in p.items() if k != "offset"} for p in m["periodic"]]}
        for m in LIBRARY["modules"]]}
    cfg = parse_modules(data)
    log: list[str] = []
    counters: dict[str, list[int]] = {}
    reg: dict[str, Callable[[], None]] = {}
    loop_ref: list[MainLoop] = []
    for name in all_function_names(cfg):
        counters[name] = []
        reg[name] = (lambda n: lambda: counters[n].append(loop_ref[0].iteration))(name)
    sch = build_schedule(cfg, reg)                       # default: optimised
    assert sch.heuristic == "optimised" and sch.hyperperiod == 20
    loop = MainLoop(sch, SimClock(0))
    loop_ref.append(loop)
    loop.run(duration_s=0.6)                             # 60 iterations, init included
    assert loop.iteration == 60
    for p in sch.periodic:
        assert counters[p.name] == [i for i in range(60) if i % p.prescaler == p.offset], p.name
    assert counters["dl.poll"] == list(range(60))
    # spreading: telem.send and nav.run (both every 10) no longer share an iteration
    offs = {p.name: p.offset for p in sch.periodic}
    assert offs["telem.send"] != offs["nav.run"]
    assert not log


def test_group_order_is_fixed() -> None:
    assert TASK_GROUPS == ("sensors", "estimation", "navigation", "control", "actuators", "core", "telemetry")


def test_fig3_fixture_runs() -> None:
    cfg = load_modules(FIXTURES / "scheduler_fig3.yaml")
    log: list[str] = []
    reg = recording_registry(all_function_names(cfg), log)
    loop = MainLoop(build_schedule(cfg), SimClock(0), registry=reg)
    loop.run_init()
    assert log == ["module3.init", "example.init"]
    log.clear()
    loop.step()
    assert log[0] == "module3.event"
    assert log.index("module3.periodic") < log.index("example.periodic")


def test_unbound_and_missing_functions() -> None:
    cfg = parse_modules(LIBRARY)
    sch = build_schedule(cfg)
    with pytest.raises(SchedulerError, match="not bound"):
        MainLoop(sch, SimClock(0))
    reg = recording_registry(all_function_names(cfg), [])
    del reg["baro.read"]
    with pytest.raises(SchedulerError, match=r"'baro.read' of module 'baro' \(<dict>"):
        sch.bind(reg)


def test_statistics_windows_and_table() -> None:
    cfg = parse_modules({"main_loop_hz": 500, "select": ["imu", "tm"], "modules": [
        {"name": "imu", "task_group": "sensors", "event": ["ev"],
         "periodic": [{"function": "imu", "freq": 500}]},
        {"name": "tm", "task_group": "telemetry", "periodic": [{"function": "tm", "freq": 50}]}]})
    noop: Callable[[], None] = lambda: None  # noqa: E731
    loop = MainLoop(build_schedule(cfg, {"ev": noop, "imu": noop, "tm": noop}), SimClock(0), world_step=noop)
    loop.run(duration_s=5.0)
    st = loop.stats
    s = st.group_summary("sensors")
    assert s["calls"] == 2500 and s["windows"] == 2 and s["sim_hz"] == pytest.approx(500)
    assert s["freq_hz"] > 0 and s["min_us"] <= s["avg_us"] <= s["max_us"]
    t = st.group_summary("telemetry")
    assert t["calls"] == 250 and t["windows"] == 0 and t["sim_hz"] == pytest.approx(50)
    assert t["freq_hz"] > 0                           # from the partial window
    assert st.group_summary("events")["calls"] == 2500
    assert st.group_summary("world")["calls"] == 2500
    assert st.group_summary("control")["calls"] == 0
    wins = st.windows("sensors")
    assert len(wins) == 2 and all(w.calls == 1000 for w in wins)
    d = st.as_dict(include_windows=True)
    assert d["iterations"] == 2500 and d["sim_time_s"] == pytest.approx(5.0)
    assert len(d["groups"]["events"]["window_list"]) == 2
    assert d["realtime_factor"] > 1
    table = st.table()
    for name in ("events", "sensors", "telemetry", "world", "overruns", "iterations 2500"):
        assert name in table


def test_overruns_and_worst_iteration() -> None:
    cfg = parse_modules({"main_loop_hz": 1000, "select": ["slow"], "modules": [
        {"name": "slow", "task_group": "control",
         "periodic": [{"function": "busy", "freq": 100, "offset": 5}, {"function": "fast", "freq": 1000}]}]})

    def busy() -> None:
        end = time.perf_counter() + 0.004
        while time.perf_counter() < end:
            pass

    loop = MainLoop(build_schedule(cfg, {"busy": busy, "fast": lambda: None}), SimClock(0))
    loop.run(duration_s=0.03)
    st = loop.stats
    assert st.overruns >= 3
    assert st.worst_iteration in (5, 15, 25) and st.worst_ns >= 4_000_000
    assert st.as_dict()["worst_iteration"]["sim_time_s"] == pytest.approx(st.worst_iteration / 1000)


def test_real_time_pacing() -> None:
    cfg = parse_modules({"main_loop_hz": 100, "select": ["a"], "modules": [
        {"name": "a", "task_group": "core", "periodic": [{"function": "f", "freq": 100}]}]})
    loop = MainLoop(build_schedule(cfg, {"f": lambda: None}), SimClock(speedup=1))
    t0 = time.perf_counter()
    assert loop.run(duration_s=0.1) == 10
    assert time.perf_counter() - t0 >= 0.085


def test_a_stall_is_caught_up_for_at_most_max_lag_then_given_up() -> None:
    """A paced loop that stalled runs back to back for ``max_lag_s`` of wall time at most (ArduPilot's
    SITL bounds its sleep debt the same way), then paces again: no burst of simulated seconds."""
    cfg = parse_modules({"main_loop_hz": 100, "select": ["a"], "modules": [
        {"name": "a", "task_group": "core", "periodic": [{"function": "f", "freq": 100}]}]})
    ran: list[tuple[float, float]] = []
    clock = SimClock(speedup=1, max_lag_s=0.05)

    def f() -> None:
        ran.append((clock.now(), time.perf_counter()))
        if len(ran) == 5:
            time.sleep(0.4)  # a 0.4 s stall (a starved process)

    loop = MainLoop(build_schedule(cfg, {"f": f}), clock)
    loop.run(duration_s=0.3)
    assert clock.slips >= 1 and clock.given_up_s >= 0.3
    after = [(sim, wall) for sim, wall in ran[5:]]
    # periods run within 5 ms of wall time after the stall: only the 50 ms of debt is caught up
    burst = [sim for sim, wall in after if wall - after[0][1] < 0.005]
    assert len(burst) <= 7, f"{len(burst)} periods raced through after the stall"
    # the unbounded clock would have caught up all 0.4 s; this one ran 0.3 s of simulation in >= 0.6 s
    assert ran[-1][1] - ran[0][1] >= 0.55
    with pytest.raises(ValueError, match="max_lag_s"):
        SimClock(1.0, max_lag_s=0.0)


def test_stop_event_and_exception_note() -> None:
    cfg = parse_modules({"main_loop_hz": 100, "select": ["a"], "modules": [
        {"name": "a", "task_group": "core", "periodic": [{"function": "f", "freq": 100}]}]})
    stop = threading.Event()
    calls = [0]

    def f() -> None:
        calls[0] += 1
        if calls[0] == 20:
            stop.set()
        if calls[0] == 1000:
            raise RuntimeError("boom")

    loop = MainLoop(build_schedule(cfg, {"f": f}), SimClock(0))
    n = loop.run(stop_event=stop)
    assert 20 <= n <= 28
    stop.clear()
    assert loop.run(duration_s=1.0, stop_event=stop) == 100
    with pytest.raises(RuntimeError, match="boom") as info:
        loop.run(duration_s=100.0)
    assert any("in main loop iteration 999" in note for note in info.value.__notes__)


@pytest.mark.parametrize("stats", [True, False])
def test_the_autopilot_times_its_loop_only_when_asked(stats: bool, capsys: pytest.CaptureFixture[str],
                                                      tmp_path: Path) -> None:
    from autopilot_model.sitl import main

    argv = ["--speedup", "0", "--duration", "0.5", "--no-persist", "--state-dir", str(tmp_path),
            "--mavlink", "udpin:127.0.0.1:0", *(["--stats"] if stats else [])]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert ("sensors" in out and "overruns" in out) is stats  # the table of Sec. 5, only with --stats
