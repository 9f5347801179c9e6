"""Bench: delegation time for a 100-node tree (seed 000 Sec. III-A).

The constraint check of delegation (:mod:`companion.tst.constraints`) on a synthetic Task Specification
Tree: a sequence node (S) with 99 leaves alternating *fly-to* and *scan-ground* (100 nodes). Each leaf
has a qualitative speed (``slow | standard | fast`` mapped to 1 / 3 / 5 m/s; every fourth is given as
``fast``), an altitude interval [2, 40] m under the envelope ceiling (a platform constraint, as
``get_constraints()`` returns it), a path length (fly-to 50-300 m, scan-ground 400-1500 m) and its
duration ``length / speed`` plus a hover time, all under one shared endurance constraint.

Three cases, each built and solved (``solve(prefer="standard")``) ``--runs`` times (time: mean and max
in ms):

* feasible: the endurance is halfway between the flight at standard and at fast speed, so the solver
  chooses which legs fly fast (as few as possible) and fixes every speed, altitude and duration;
* altitude: one leaf's given altitude is above the ceiling; the conflict search names the two;
* endurance: the endurance is shorter than the whole flight at fast speed; the conflict names the
  endurance, the sum and every leaf's free speed set.

A second table times the whole of :func:`companion.tst.delegation.delegate` (check, constraints, first
solve, plans with scan patterns, second solve with the durations, expansion) on 100-node mission trees
on the bundled outdoor platform (its battery made large enough, except in the rejected case):

* fly-to: S of take-off, 97 fly-to to random points inside the fence (speeds ``standard | fast``), land;
* scan-ground: S of take-off, 49 fly-to and 48 scan-ground nodes over 30 x 30 m areas (each expands
  into its waypoints' fly-to children), land;
* fly-to, endurance 85 %: the fly-to tree with an endurance of 85 % of its flight at standard speed: the
  second solve flies as few legs fast as needed;
* fly-to, endurance 50 %: shorter than the flight at fast speed: rejected, the conflict search names the
  endurance and the speeds.
"""

from __future__ import annotations

import argparse
import dataclasses
import random
import statistics
import sys
import time

from bench.common import machine, table
from companion.tst.constraints import ConstraintProblem, Solution
from companion.tst.delegation import Delegation, delegate
from companion.tst.delegation_plan import local_to_geopoint
from companion.tst.platform import Platform, bundled_platform
from companion.tst.spec import Mission, mission_from_dict

SPEEDS = {"slow": 1.0, "standard": 3.0, "fast": 5.0}
CEILING_M = 30.0
HOVER_S = 5.0


def leaves(nodes: int, seed: int) -> list[tuple[str, str, float]]:
    """(node id, type, path length m) of the leaves of an S root: ``nodes - 1`` of them."""
    rng = random.Random(seed)
    out = []
    for i in range(1, nodes):
        kind = "fly-to" if i % 2 else "scan-ground"
        length = rng.uniform(50, 300) if kind == "fly-to" else rng.uniform(400, 1500)
        out.append((f"n{i}", kind, length))
    return out


def build(tree: list[tuple[str, str, float]], endurance_s: float, bad_altitude: bool) -> ConstraintProblem:
    """The constraint problem of the tree and the platform (what delegation hands the solver)."""
    p = ConstraintProblem()
    p.variable("endurance_left", value=endurance_s, label=f"endurance_left {endurance_s:.0f} s",
               reason="battery")
    p.variable("ceiling", value=CEILING_M, label=f"envelope ceiling {CEILING_M:g} m")
    for k, (node, kind, length) in enumerate(tree):
        given = "fast" if k % 4 == 3 else None
        p.qualitative(f"{node}.speed", SPEEDS, allowed=given, reason="max 5 m/s")
        if bad_altitude and k == len(tree) // 2:
            p.variable(f"{node}.altitude", value=35, label=f"{node}.altitude = 35 ({kind}, given)")
        else:
            p.variable(f"{node}.altitude", lo=2, hi=40)
        p.add(f"{node}.altitude <= ceiling", label=f"{node}.altitude <= envelope ceiling")
        p.duration_at_speed(f"{node}.duration", length, f"{node}.speed", extra_s=HOVER_S)
    p.add(" + ".join(f"{n}.duration" for n, _, _ in tree) + " <= endurance_left",
          label="sum of the durations <= endurance_left")
    return p


def run(tree: list[tuple[str, str, float]], endurance_s: float, bad_altitude: bool,
        runs: int) -> tuple[list[float], list[float], Solution, ConstraintProblem]:
    build_ms, solve_ms = [], []
    sol = p = None
    for _ in range(runs):
        t0 = time.perf_counter()
        p = build(tree, endurance_s, bad_altitude)
        t1 = time.perf_counter()
        sol = p.solve(prefer="standard")
        t2 = time.perf_counter()
        build_ms.append((t1 - t0) * 1e3)
        solve_ms.append((t2 - t1) * 1e3)
    assert sol is not None and p is not None
    return build_ms, solve_ms, sol, p


def mission_tree(platform: Platform, nodes: int, scans: bool, seed: int) -> Mission:
    """S(take-off, nodes - 3 leaves, land): fly-to (and scan-ground) inside the outdoor fence."""
    rng = random.Random(seed)

    def geo(n: float, e: float, up: float | None = None) -> list[float]:
        lat, lon, alt = local_to_geopoint((n, e, up or 0.0), platform)
        return [lat, lon] if up is None else [lat, lon, alt]

    leaves: list[dict] = [{"type": "take-off"}]
    for i in range(nodes - 3):
        n, e = rng.uniform(-150, 150), rng.uniform(-150, 150)
        if scans and i % 2:
            area = [geo(n, e), geo(n, e + 30), geo(n + 30, e + 30), geo(n + 30, e)]
            leaves.append({"type": "scan-ground", "params": {"area": area, "speed": "standard | fast"}})
        else:
            leaves.append({"type": "fly-to", "params": {"position": geo(n, e, rng.uniform(10, 40)),
                                                         "speed": "standard | fast"}})
    leaves.append({"type": "land"})
    return mission_from_dict({"mission": f"bench-{nodes}", "tree": {"type": "S", "children": leaves}})


def run_delegate(mission: Mission, platform: Platform, runs: int) -> tuple[list[float], Delegation]:
    times, result = [], None
    for _ in range(runs):
        result = delegate(mission, platform)
        times.append(result.seconds * 1e3)
    assert result is not None
    return times, result


def delegate_table(nodes: int, runs: int, seed: int) -> str:
    base = bundled_platform("outdoor")
    roomy = dataclasses.replace(base, battery_capacity_s=1e6, reserve_s=0.0)
    rows = []
    for name, scans in (("fly-to", False), ("scan-ground", True)):
        m = mission_tree(base, nodes, scans, seed)
        times, d = run_delegate(m, roomy, runs)
        assert d.accepted, d.reasons
        fast = sum(1 for v in d.fixed.values() if v == "fast")
        rows.append((name, nodes, sum(1 for _ in d.mission.root.iter()), d.waypoints, round(d.expected_s),
                     statistics.mean(times), max(times), f"accepted ({fast} fast)"))
        if not scans:  # an endurance of 85 % of the flight at standard speed: some legs fly fast
            tight = dataclasses.replace(roomy, battery_capacity_s=0.85 * d.expected_s)
            times, r = run_delegate(m, tight, runs)
            assert r.accepted, r.reasons
            fast = sum(1 for v in r.fixed.values() if v == "fast")
            rows.append(("fly-to, endurance 85 %", nodes, nodes, 0, round(r.expected_s),
                         statistics.mean(times), max(times), f"accepted ({fast} fast)"))
            # half of it: not even all fast is short enough
            short = dataclasses.replace(roomy, battery_capacity_s=0.5 * d.expected_s)
            times, r = run_delegate(m, short, runs)
            assert not r.accepted
            rows.append(("fly-to, endurance 50 %", nodes, nodes, 0, "-", statistics.mean(times), max(times),
                         f"rejected ({len(r.solution.conflict) if r.solution else 0} constraints named)"))
    return table(["tree", "nodes", "nodes expanded", "scan waypoints", "expected s", "delegate mean",
                  "delegate max", "result"], rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=100, help="nodes of the tree (an S root and its leaves)")
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    tree = leaves(args.nodes, args.seed)
    fast_s = sum(length / SPEEDS["fast"] + HOVER_S for _, _, length in tree)
    standard_s = sum(length / SPEEDS["standard"] + HOVER_S for _, _, length in tree)
    cases = [
        ("feasible", (fast_s + standard_s) / 2, False),
        ("altitude above ceiling", standard_s, True),
        ("endurance exceeded", 0.95 * fast_s, False),
    ]
    rows = []
    for name, endurance, bad_alt in cases:
        b, s, sol, p = run(tree, endurance, bad_alt, args.runs)
        total = [x + y for x, y in zip(b, s, strict=True)]
        if sol.ok:
            fast = sum(1 for c in sol.choices.values() if c == "fast")
            result = f"accepted ({fast} of {len(sol.choices)} fast)"
        else:
            result = f"rejected ({len(sol.conflict)} constraints named)"
        rows.append((name, len(p.variables), len(p.labels), statistics.mean(b), statistics.mean(s),
                     max(s), statistics.mean(total), max(total), result))
    print(f"# bench_delegation ({machine()})\n")
    print(f"Constraint check of a {args.nodes}-node tree (S + {len(tree)} fly-to / scan-ground leaves), "
          f"{args.runs} runs per case, times in ms\n")
    print(table(["case", "variables", "constraints", "build mean", "solve mean", "solve max", "total mean",
                 "total max", "result"], rows))
    print(f"\ndelegate() of {args.nodes}-node mission trees on the outdoor platform, {args.runs} runs, "
          "times in ms\n")
    print(delegate_table(args.nodes, args.runs, args.seed))
    return 0


if __name__ == "__main__":
    start = time.monotonic()
    code = main()
    print(f"\n(wall {time.monotonic() - start:.0f} s)")
    sys.exit(code)
