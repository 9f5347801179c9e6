"""Bench: distributed allocation quality against the optimum (seed 003 Sec. III-B; CBBA).

Seeded random instances run through the team simulator (:class:`companion.team.sim.TeamSim`: kinematic
vehicles and a station, each with the real GroupState / TeamLink over a lossy MemoryBus, simulated time)
at 0, 10, 20 and 40 % packet loss, with the greedy policy and with CBBA:

* greedy (one task per vehicle): N = 3..6 vehicles and N short patrol lines (5 m, held until cancelled,
  so the assignment is one-to-one) at random points in a 1 km square, run until every task is flown
  (ACTIVE) by one vehicle; team cost = the sum over vehicles of the flight time
  (:class:`~companion.team.cost.CostModel`) from its start to the task it flies; optimum:
  ``scipy.optimize.linear_sum_assignment`` on that cost matrix;
* CBBA (several tasks per vehicle): N = 2..4 vehicles and N + 1..6 visits, the policy's bundle
  ``max_tasks`` = ceil(M / N) + 1 (bundles refill as visits finish, so a vehicle may fly more); team cost
  = the sum over vehicles of the time each spent moving (the point mass's own flight, so metres flown
  toward tasks later lost to another vehicle are charged too; the metres flown are shown beside those of
  the optimum's paths); optimum: exact, every subset's best order (all permutations) per vehicle and a DP
  over the partitions of the tasks, with no limit on the tasks per vehicle (the team is not limited
  either).

Quality = optimum / team cost: at most 1 up to a hair (a visit is reached within 2 m, the model's legs end
on the point). Also: time (simulated s) after which the assignment stayed conflict-free, the conflicts
declared per instance, the instances where some task was held by two vehicles at once at some step (every
step of the run sampled, not only its end) and the longest such stretch (how long conflicts last).
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
from companion.team.geometry import LocalFrame, distance_m
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


def optimum_bundles(starts, tasks: list[TeamTask]) -> tuple[float, float]:
    """Exact: the best order of every subset per vehicle (any size), then the best partition (DP over
    masks); (team time s, metres of the optimum's paths)."""
    m = len(tasks)
    full = (1 << m) - 1
    best_sub: list[dict[int, tuple[float, float]]] = []
    for s in starts:
        at = FRAME.to_geo(*s)
        d = {0: (0.0, 0.0)}
        for mask in range(1, full + 1):
            idx = [j for j in range(m) if mask >> j & 1]
            paths = ([tasks[j] for j in perm] for perm in itertools.permutations(idx))
            d[mask] = min((MODEL.path_time(at, p), path_m(at, p)) for p in paths)
        best_sub.append(d)
    f: dict[int, tuple[float, float]] = {0: (0.0, 0.0)}
    for d in best_sub:
        g: dict[int, tuple[float, float]] = {}
        for mask, (val, metres) in f.items():
            rest = full & ~mask
            sub = rest
            while True:
                nm = mask | sub
                v = val + d[sub][0]
                if v < g.get(nm, (math.inf, 0.0))[0]:
                    g[nm] = (v, metres + d[sub][1])
                if sub == 0:
                    break
                sub = (sub - 1) & rest
        f = g
    return f[full]


def path_m(at, tasks: list[TeamTask]) -> float:
    """Horizontal metres of a path of visits from ``at``."""
    total, here = 0.0, at
    for t in tasks:
        total += distance_m(here, t.points[0])[0]
        here = t.points[0]
    return total


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
        opt, opt_m = optimum_bundles(starts, tasks)
        cost = sum(v.moving_s for v in sim.vehicles)  # every second flown, toward tasks later lost too
        flown_m = sum(v.flown_m for v in sim.vehicles)
        most = max(sum(1 for h in r.done_by.values() if h == v.member) for v in sim.vehicles)
    return {"quality": opt / cost if done and cost > 0 else 0.0, "done": float(done),
            "settle": r.conflict_free_at if r.conflict_free_at is not None else math.nan,
            "conflicts": float(r.conflicts), "twice": float(bool(r.held_twice_s)),
            "twice_s": r.held_twice_longest_s,
            "flown_m": flown_m if policy != "greedy" else math.nan,
            "opt_m": opt_m if policy != "greedy" else math.nan,
            "most": float(most) if policy != "greedy" else 1.0, "max_tasks": float(max_tasks)}


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
            flown = [x["flown_m"] / x["opt_m"] for x in res if x["opt_m"] and not math.isnan(x["opt_m"])]
            rows.append([policy, f"{loss:.0%}", round(statistics.median(q), 4), round(pct(q, 0.1), 4),
                         round(min(q), 4), round(max(q), 4),
                         round(statistics.median(flown), 3) if flown else "-",
                         sum(x["most"] > x["max_tasks"] for x in res) if policy != "greedy" else "-",
                         f"{sum(x['done'] for x in res):.0f}/{len(res)}",
                         int(sum(x["twice"] for x in res)), max(x["twice_s"] for x in res),
                         round(statistics.median(settle), 2) if settle else "-",
                         round(pct(settle, 0.95), 2) if settle else "-",
                         round(statistics.mean(x["conflicts"] for x in res), 2),
                         round(time.perf_counter() - t0, 1)])
            print(f"  {policy} {loss:.0%} done", file=sys.stderr, flush=True)
    print(table(["policy", "loss", "quality median", "p10", "min", "max", "metres flown / optimum's (median)",
                 "instances where a vehicle flew more than max_tasks", "all done",
                 "instances with a task held twice", "held twice longest s",
                 "conflict-free s (median)", "(p95)", "conflicts/inst", "wall s"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
