"""``taskflight team sim``: the team simulator from the command line.

The parser is light (nothing heavy imported); :func:`run_sim` loads the task file, runs
:class:`~companion.team.sim.TeamSim` on simulated time, prints each assignment change as it happens and a
final table of the tasks.
"""

from __future__ import annotations

import argparse
import sys


def add_sim_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--vehicles", type=int, default=3, metavar="N", help="number of vehicles (default 3)")
    p.add_argument("--tasks", required=True, metavar="FILE", help="team task file (YAML), e.g. "
                   "mission_specs/team_tasks.yaml")
    p.add_argument("--loss", type=float, default=0.0, metavar="P", help="fraction of team packets dropped")
    p.add_argument("--policy", choices=("greedy", "cbba"), default="greedy", help="allocation policy")
    p.add_argument("--seed", type=int, default=0, help="random seed (packet loss, start offsets)")
    p.add_argument("--duration", type=float, default=600.0, metavar="S",
                   help="simulated seconds at most (stops earlier once every task is done or cancelled)")
    p.add_argument("--max-tasks", type=int, default=3, help="CBBA: tasks per vehicle (default 3)")


def run_sim(args: argparse.Namespace) -> int:
    # loaded when the command runs: the command line starts without shapely and the team layer
    from companion.team.sim import TeamSim
    from companion.team.taskfile import load_task_file
    from taskflight_common.yamlio import ConfigError

    try:
        script = load_task_file(args.tasks)
    except ConfigError as exc:
        print(f"taskflight team sim: error: {exc}", file=sys.stderr)
        return 2
    if args.vehicles < 1 or not 0.0 <= args.loss <= 1.0 or args.duration <= 0 or args.max_tasks < 1:
        print("taskflight team sim: error: --vehicles >= 1, --loss in 0..1, --duration > 0, --max-tasks >= 1",
              file=sys.stderr)
        return 2

    def show(now: float, tid: int, state: object, holder: int | None) -> None:
        who = f" -> vehicle {holder}" if holder is not None else ""
        print(f"t={now:7.2f} s  task {tid:4d} {getattr(state, 'value', state)}{who}", flush=True)

    sim = TeamSim(script, args.vehicles, loss=args.loss, policy=args.policy, seed=args.seed,
                  max_tasks=args.max_tasks, on_change=show)
    r = sim.run(args.duration, stop_when_done=True)
    print()
    print(f"{'task':>5} {'kind':<13} {'name':<16} {'state':<11} {'holder':>6} {'done by':>7}")
    for tid, (t, state, holder) in r.tasks.items():
        print(f"{tid:>5} {t.kind.value:<13} {t.name[:16]:<16} {state.value:<11} "
              f"{holder if holder is not None else '-':>6} {r.done_by.get(tid, '-'):>7}")
    cf = f"{r.conflict_free_at:.2f} s" if r.conflict_free_at is not None else "not reached"
    print(f"\n{args.vehicles} vehicles, policy {args.policy}, loss {args.loss:g}: "
          f"{r.duration:.1f} s simulated, "
          f"{r.conflicts} conflicts declared, conflict-free since {cf}, "
          f"tasks held twice at some step: {len(r.held_twice_s)} "
          f"(longest {r.held_twice_longest_s:.2f} s, every step sampled)")
    return 0
