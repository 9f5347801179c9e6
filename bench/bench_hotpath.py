"""Costs on hot paths, per call: the model's state interface, main-loop overhead and setpoint generator;
the companion's belief memory (a two-pattern join over 900 beliefs, a cached text query).

    python -m bench.bench_hotpath
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

from autopilot_model.modules.guidance import Envelope, SetpointGenerator
from autopilot_model.scheduler import TASK_GROUPS, MainLoop, build_schedule, parse_modules
from autopilot_model.state import StateInterface, euler_to_quat
from bench.common import machine, table
from taskflight_common.clock import SimClock


def per_call_us(fn: Callable[[], object], n: int = 50000) -> float:
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t0) / n * 1e6


def beliefs_rows() -> list[tuple[str, float]]:
    """The executive layer's memory of beliefs, consulted (seed 001 Sec. 6.2.4) as an IF or a WHILE does."""
    from companion.behaviors.belief_syntax import parse_query
    from companion.behaviors.beliefs import BeliefMemory

    m = BeliefMemory()
    for i in range(300):
        m.add(f"object({i}, {'battery' if i % 10 == 0 else 'obstacle'})")
        m.add(f"charge({i}, {'full' if i % 20 == 0 else 'low'})")
        m.add(f"position({i}, ({i}.0, 1.0, 2.0))")
    q = parse_query("object(?x, battery), charge(?x, full)")
    return [("beliefs: consult, 2 patterns joined over 900 beliefs (15 answers)",
             per_call_us(lambda: m.consult(q), 2000)),
            ("beliefs: holds, one text belief (parsed once, cached)",
             per_call_us(lambda: m.holds("charge(150, low)"), 2000))]


def main() -> None:
    logging.basicConfig(level=logging.WARNING)
    rows = []
    s = StateInterface(origin=(47.0, 8.0, 400.0))
    q = euler_to_quat((0.1, 0.2, 0.3))
    p = (1.0, 2.0, -3.0)
    rows.append(("state: set_position_ned", per_call_us(lambda: s.set_position_ned(p))))
    rows.append(("state: set_quat", per_call_us(lambda: s.set_quat(q))))
    rows.append(("state: publish_estimate (5 quantities)",
                 per_call_us(lambda: s.publish_estimate(0, p, p, q, p, p))))
    rows.append(("state: publish (the estimator's buffer written)", per_call_us(lambda: s.publish(0))))
    rows.append(("state: read vector (the control chain's read)", per_call_us(lambda: s.vector)))

    def publish_then_tuple() -> object:
        s.publish(0)
        return s.position_ned

    rows.append(("state: publish + first position_ned read (tuple from the vector)",
                 per_call_us(publish_then_tuple)))
    rows.append(("state: read position_ned", per_call_us(lambda: s.position_ned)))

    def write_then_euler() -> object:
        s.set_quat(q)
        return s.euler

    rows.append(("state: set_quat + first euler read (one conversion)", per_call_us(write_then_euler)))
    rows.append(("state: geodetic read after a write (pymap3d)", per_call_us(
        lambda: (s.set_position_ned(p), s.position_geodetic), 2000)))

    mods = [{"name": f"m{i}", "task_group": TASK_GROUPS[i % 7],
             "periodic": [{"function": f"m{i}.p", "freq": 500}, {"function": f"m{i}.s", "freq": 10}]}
            for i in range(20)]
    cfg = parse_modules({"main_loop_hz": 500, "modules": mods, "select": [m["name"] for m in mods]})
    reg = {f"m{i}.{k}": (lambda: None) for i in range(20) for k in "ps"}
    loop = MainLoop(build_schedule(cfg, reg), SimClock(0), world_step=lambda: None)
    loop.run_init()
    rows.append(("main loop: one iteration, 20 no-op modules x 2 functions", per_call_us(loop.step, 20000)))

    for name, env in (("box", Envelope(box=(-100, 100, -100, 100), alt_floor=0, alt_ceiling=50)),
                      ("polygon", Envelope(polygon=[(-100, -100), (100, -100), (120, 0), (100, 100),
                                                    (-100, 100)], alt_floor=0, alt_ceiling=50))):
        g = SetpointGenerator(env, 0.002)
        g.reset((0.0, 0.0, -10.0))
        g.set_position_target((80.0, 30.0, -20.0), speed=5.0)
        rows.append((f"guidance: update, cruising, {name} envelope", per_call_us(g.update, 5000)))
        g.set_velocity_target((0.0, 8.0, 0.0))
        for _ in range(20000):
            g.update()
        rows.append((f"guidance: update, pressed against the fence, {name}", per_call_us(g.update, 5000)))
    rows += beliefs_rows()
    print("bench_hotpath: wall cost per call")
    print(f"machine: {machine()}")
    print(table(("operation", "us per call"),
                [(n, round(u, 3) if not math.isnan(u) else u) for n, u in rows]))


if __name__ == "__main__":
    main()
