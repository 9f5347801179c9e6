"""Offsets of periodic functions: seed 002 Sec. 4.3 and Fig. 5."""

from __future__ import annotations

import random

import numpy as np
import pytest

from autopilot_model.scheduler import (
    OffsetTask,
    SchedulerError,
    build_schedule,
    evaluate,
    hyperperiod,
    naive_offsets,
    offset_report,
    optimised_offsets,
    parse_modules,
    zero_offsets,
)
from autopilot_model.scheduler.offsets import format_offset_report, load_profile

# Fig. 5: three tasks at three frequencies, hyperperiod 6 main-loop iterations (periods 2, 3, 6).
FIG5 = [OffsetTask("t1", 2), OffsetTask("t2", 3), OffsetTask("t3", 6)]


def runs(task: OffsetTask, offset: int, iterations: int) -> set[int]:
    return {i for i in range(iterations) if i % task.prescaler == offset}


def test_fig5_without_offsets_all_coincide_every_6_units() -> None:
    offsets = zero_offsets(FIG5)
    common = set.intersection(*(runs(t, o, 60) for t, o in zip(FIG5, offsets, strict=True)))
    assert sorted(common) == list(range(0, 60, 6))
    rep = evaluate(FIG5, offsets)
    assert (rep.hyperperiod, rep.coincidences, rep.max_load, rep.mean_load) == (6, 1, 3.0, 1.0)


def test_fig5_naive_offsets_never_coincide() -> None:
    offsets = naive_offsets(FIG5)      # x = 0.1, 0.2, 0.3 -> floor(x N) = 0, 0, 1
    assert offsets == [0, 0, 1]
    common = set.intersection(*(runs(t, o, 60) for t, o in zip(FIG5, offsets, strict=True)))
    assert common == set()
    assert evaluate(FIG5, offsets).coincidences == 0


def test_fig5_report() -> None:
    rep = offset_report(FIG5)
    assert list(rep) == ["none", "naive", "optimised"]
    assert rep["none"].coincidences == 1 and rep["none"].max_load == 3
    assert rep["naive"].coincidences == 0 and rep["naive"].max_load == 2
    assert rep["optimised"].coincidences == 0 and rep["optimised"].max_load == 2  # 2 is optimal here
    assert all(r.mean_load == pytest.approx(1.0) for r in rep.values())
    text = format_offset_report(rep)
    assert "naive" in text and "optimised" in text


def test_naive_sequence_follows_paparazzi() -> None:
    tasks = [OffsetTask(f"f{i}", 100) for i in range(12)]
    assert naive_offsets(tasks) == [10, 20, 30, 40, 50, 60, 70, 80, 90, 0, 10, 20]
    # an explicit offset is kept and does not consume an increment
    tasks[1] = OffsetTask("fixed", 100, fixed_offset=33)
    assert naive_offsets(tasks)[:4] == [10, 33, 20, 30]


def test_explicit_offsets_kept_by_every_heuristic() -> None:
    tasks = [OffsetTask("a", 4, fixed_offset=3), OffsetTask("b", 4), OffsetTask("c", 4, fixed_offset=3)]
    for fn in (zero_offsets, naive_offsets, optimised_offsets):
        offs = fn(tasks)
        assert offs[0] == 3 and offs[2] == 3
    assert optimised_offsets(tasks)[1] != 3


def test_optimised_spreads_equal_tasks() -> None:
    tasks = [OffsetTask(f"f{i}", 10) for i in range(10)]
    assert sorted(optimised_offsets(tasks)) == list(range(10))
    assert evaluate(tasks, optimised_offsets(tasks)).max_load == 1


def test_optimised_uses_costs() -> None:
    # a heavy 250 Hz task and a light one: the light one must go to the other phase
    tasks = [OffsetTask("heavy", 2, cost=100.0), OffsetTask("light", 2, cost=1.0),
             OffsetTask("mid", 4, cost=50.0)]
    offs = optimised_offsets(tasks)
    load = load_profile(tasks, offs)
    assert load.max() == 100.0          # the heavy task alone; light and mid go to the other phase
    assert offs[0] != offs[1] and offs[0] % 2 != offs[2] % 2


def _random_tasks(rng: random.Random, with_costs: bool) -> list[OffsetTask]:
    divisors = [1, 2, 4, 5, 10, 20, 25, 50, 100, 250, 500]
    n = rng.randint(2, 30)
    return [OffsetTask(f"f{i}", rng.choice(divisors),
                       cost=rng.uniform(0.1, 100.0) if with_costs else 1.0,
                       fixed_offset=None) for i in range(n)]


@pytest.mark.parametrize("with_costs", [False, True])
def test_optimised_never_worse_than_naive_on_random_sets(with_costs: bool) -> None:
    rng = random.Random(1234 + with_costs)
    greedy_wins = greedy_losses = 0
    for _ in range(150):
        tasks = _random_tasks(rng, with_costs)
        rep = offset_report(tasks)
        assert rep["optimised"].max_load <= rep["naive"].max_load + 1e-9
        assert rep["optimised"].max_load <= rep["none"].max_load + 1e-9
        # lower bounds: the mean, and the functions that run in every iteration
        assert rep["optimised"].max_load >= rep["optimised"].mean_load - 1e-9
        assert rep["optimised"].max_load >= sum(t.cost for t in tasks if t.prescaler == 1) - 1e-9
        # the heuristic itself, without falling back on naive, should rarely lose
        raw = evaluate(tasks, optimised_offsets(tasks, guard=False)).max_load
        greedy_wins += raw < rep["naive"].max_load - 1e-9
        greedy_losses += raw > rep["naive"].max_load + 1e-9
    assert greedy_losses <= 2        # 0 with these seeds
    assert greedy_wins >= 100        # strictly better than naive in most sets


def test_load_profile_matches_definition() -> None:
    tasks = [OffsetTask("a", 2, 1.0), OffsetTask("b", 5, 2.0)]
    load = load_profile(tasks, [1, 3])
    expected = np.array([sum(t.cost for t, o in zip(tasks, (1, 3), strict=True) if i % t.prescaler == o)
                         for i in range(10)])
    assert np.array_equal(load, expected)


def test_hyperperiod_limit() -> None:
    assert hyperperiod([2, 3, 4]) == 12
    assert hyperperiod([]) == 1
    with pytest.raises(SchedulerError, match="hyperperiod"):
        hyperperiod([997, 991, 983])


def test_schedule_offsets_and_report() -> None:
    cfg = parse_modules({"main_loop_hz": 500, "select": ["a"], "modules": [
        {"name": "a", "task_group": "core", "periodic": [
            {"function": "p1", "freq": 50}, {"function": "p2", "freq": 50}, {"function": "p3", "freq": 50},
            {"function": "p4", "freq": 25, "offset": 4}]}]})
    for heuristic in ("none", "naive", "optimised"):
        sch = build_schedule(cfg, heuristic=heuristic)
        assert sch.heuristic == heuristic
        assert [p.prescaler for p in sch.periodic] == [10, 10, 10, 20]
        assert sch.periodic[3].offset == 4 and sch.periodic[3].fixed
    assert [p.offset for p in build_schedule(cfg, heuristic="naive").periodic] == [1, 2, 3, 4]
    assert [p.offset for p in build_schedule(cfg, heuristic="none").periodic] == [0, 0, 0, 4]
    rep = offset_report(build_schedule(cfg))
    assert rep["optimised"].max_load == 1 and rep["none"].max_load == 3
    # default heuristic is the optimised one; costs change the load
    assert build_schedule(cfg).heuristic == "optimised"
    sch = build_schedule(cfg, costs={"p1": 5.0})
    assert sch.periodic[0].cost == 5.0
    with pytest.raises(ValueError, match="unknown offset heuristic"):
        build_schedule(cfg, heuristic="clever")
