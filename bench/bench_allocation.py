"""Bench: distributed allocation quality against the optimum (seed 003 Sec. III-B; CBBA).

Seeded random instances run through the team simulator (:class:`companion.team.sim.TeamSim`: kinematic
vehicles and a station, each with the real GroupState / TeamLink over a lossy MemoryBus, simulated time)
at 0, 10, 20 and 40 % packet loss, with the greedy policy and with CBBA:

* greedy (one task per vehicle): N = 3..6 vehicles and N short patrol lines (5 m, held until cancelled,
  so the assignment is one-to-one) at random points in a 1 km square, run until every task is flown
  (ACTIVE) by one vehicle; team cost = the sum over vehicles of the flight time
  (:class:`~companion.team.cost.CostModel`) from its start to the task it flies; optimum:
  ``scipy.optimize.linear_sum_assignment`` on that cost matrix;
* CBBA (several tasks per vehicle): N = 2..4 vehicles and N + 1..6 visits, ``max_tasks`` = ceil(M / N) + 1;
  team cost = the sum over vehicles of the path time of the tasks it completed, in the order it completed
  them; optimum: exact, every subset's best order (all permutations) per vehicle and a DP over the
  partitions of the tasks (within ``max_tasks`` each).

Quality = optimal / team cost (<= 1). Also: time (simulated s) after which the assignment stayed
conflict-free, the conflicts declared per instance, the tasks held twice at the end (must be 0), and the
longest a task was held by two vehicles at once during the run (every step sampled: how long conflicts last).
"""

from __future__ import annotations

import argparse
import itertools
import math
import random
import statistics
import sys
import time

import numpy as np
from scipy.optimize import linear_sum_assignment

from bench.common import machine, pct, table
from companion.team.cost import CostModel
from companion.team.geometry import LocalFrame
from companion.team.sim import TeamSim
from companion.team.taskfile import ScriptedTask, TaskScript
from companion.team.tasks import TaskDef
from companion.team.types import TaskKind, TeamTask

HOME = (-35.363261, 149.165230)
FRAME = LocalFrame(*HOME)
MODEL = CostModel(speed=5.0, accel=2.5, climb_speed=2.5)
HALF = 500.0
ALT = 20.0
PATROL_M = 5.0


Starts = list[tuple[float, float, float]]


def instance(seed: int, policy: str) -> tuple[Starts, list[tuple[float, float]], int]:
    """(vehicle starts in local m, task points in local m, max_tasks)."""
    rng = random.Random(seed)
    if policy == "greedy":
        n = rng.randint(3, 6)
        m = n
        max_tasks = 1
    else:
        n = rng.randint(2, 4)
        m = rng.randint(n + 1, 6)
        max_tasks = math.ceil(m / n) + 1
    starts = [(rng.uniform(-HALF, HALF), rng.uniform(-HALF, HALF), ALT) for _ in range(n)]
    tasks = [(rng.uniform(-HALF, HALF), rng.uniform(-HALF, HALF)) for _ in range(m)]
    return starts, tasks, max_tasks


def team_tasks(points: list[tuple[float, float]]) -> list[TeamTask]:
    return [TeamTask(id=101 + j, version=1, kind=TaskKind.VISIT, points=(FRAME.to_geo(x, y, ALT),))
            for j, (x, y) in enumerate(points)]


def optimum_one_each(starts, tasks: list[TeamTask]) -> tuple[float, np.ndarray]:
    c = np.array([[MODEL.cost(FRAME.to_geo(*s), t) for t in tasks] for s in starts])
    r, k = linear_sum_assignment(c)
    return float(c[r, k].sum()), c


def optimum_bundles(starts, tasks: list[TeamTask], max_tasks: int) -> float:
    """Exact: the best order of every subset per vehicle, then the best partition (DP over masks)."""
    m = len(tasks)
    full = (1 << m) - 1
    best_sub: list[dict[int, float]] = []
    for s in starts:
        at = FRAME.to_geo(*s)
        d = {0: 0.0}
        for mask in range(1, full + 1):
            idx = [j for j in range(m) if mask >> j & 1]
            if len(idx) > max_tasks:
                continue
            d[mask] = min(MODEL.path_time(at, [tasks[j] for j in perm])
                          for perm in itertools.permutations(idx))
        best_sub.append(d)
    f = {0: 0.0}
    for d in best_sub:
        g: dict[int, float] = {}
        for mask, val in f.items():
            rest = full & ~mask
            sub = rest
            while True:
                if sub in d:
                    nm = mask | sub
                    v = val + d[sub]
                    if v < g.get(nm, math.inf):
                        g[nm] = v
                if sub == 0:
                    break
                sub = (sub - 1) & rest
        f = g
    return f[full]


def all_active(sim: TeamSim, m: int) -> bool:
    """Every task flown (ACTIVE) by one vehicle, as the station sees it."""
    holders = [sim.ledger.holder(i) for i in sim.ledger.ids() if sim.ledger.state(i).value == "active"]
    return len(holders) == m and len(set(holders)) == m


def run_one(seed: int, policy: str, loss: float) -> dict[str, float]:
    starts, pts, max_tasks = instance(seed, policy)
    tasks = team_tasks(pts)
    if policy == "greedy":
        # short patrols: held until the end, so the final claims are the one-to-one assignment
        script = TaskScript("bench", HOME, None, tuple(
            ScriptedTask(TaskDef("patrol_line", (FRAME.to_geo(x, y, ALT), FRAME.to_geo(x + PATROL_M, y, ALT)),
                                 altitude=ALT), at=0.0) for x, y in pts))
        tasks = [TeamTask(id=101 + j, version=1, kind=TaskKind.PATROL_LINE,
                          points=(FRAME.to_geo(x, y, ALT), FRAME.to_geo(x + PATROL_M, y, ALT)))
                 for j, (x, y) in enumerate(pts)]
    else:
        script = TaskScript("bench", HOME, None, tuple(
            ScriptedTask(TaskDef("visit", (FRAME.to_geo(x, y, ALT),), altitude=ALT), at=0.0) for x, y in pts))
    sim = TeamSim(script, len(starts), loss=loss, policy=policy, seed=seed, max_tasks=max_tasks,
                  starts=starts, model=MODEL, dt=0.5)
    if policy == "greedy":
        while sim.now < 900.0 and not all_active(sim, len(tasks)):
            sim.step()
        r = sim.result()
        holders = {tid: h for tid, (_t, st, h) in r.tasks.items() if st.value == "active"}
        done = len(holders) == len(tasks) and len(set(holders.values())) == len(tasks)
        opt, c = optimum_one_each(starts, tasks)
        cost = sum(c[holders[t.id] - 1, j] for j, t in enumerate(tasks) if t.id in holders)
    else:
        r = sim.run(900.0, stop_when_done=True)
        done = len(r.done_by) == len(tasks)
        opt = optimum_bundles(starts, tasks, max_tasks)
        cost = 0.0
        by_id = {t.id: t for t in tasks}
        for i, s in enumerate(starts, start=1):
            mine = sorted((at, tid) for tid, at in sim.done_at.items() if r.done_by[tid] == i)
            cost += MODEL.path_time(FRAME.to_geo(*s), [by_id[tid] for _, tid in mine])
    return {"quality": opt / cost if done and cost > 0 else 0.0, "done": float(done),
            "settle": r.conflict_free_at if r.conflict_free_at is not None else math.nan,
            "conflicts": float(r.conflicts), "twice": float(r.held_twice_at_end),
            "twice_s": r.held_twice_longest_s}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--instances", type=int, default=200)
    ap.add_argument("--losses", default="0,0.1,0.2,0.4")
    ap.add_argument("--policies", default="greedy,cbba")
    args = ap.parse_args()
    losses = [float(x) for x in args.losses.split(",")]
    print(f"# allocation quality: {args.instances} instances per cell; {machine()}")
    rows = []
    for policy in args.policies.split(","):
        for loss in losses:
            t0 = time.perf_counter()
            res = [run_one(seed, policy, loss) for seed in range(args.instances)]
            q = [x["quality"] for x in res]
            settle = [x["settle"] for x in res if not math.isnan(x["settle"])]
            rows.append([policy, f"{loss:.0%}", round(statistics.median(q), 4), round(pct(q, 0.1), 4),
                         round(min(q), 4), f"{sum(x['done'] for x in res):.0f}/{len(res)}",
                         int(sum(x["twice"] for x in res)), max(x["twice_s"] for x in res),
                         round(statistics.median(settle), 2) if settle else "-",
                         round(pct(settle, 0.95), 2) if settle else "-",
                         round(statistics.mean(x["conflicts"] for x in res), 2),
                         round(time.perf_counter() - t0, 1)])
            print(f"  {policy} {loss:.0%} done", file=sys.stderr, flush=True)
    print(table(["policy", "loss", "quality median", "p10", "min", "all done", "held twice",
                 "held twice longest s",
                 "conflict-free s (median)", "(p95)", "conflicts/inst", "wall s"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
