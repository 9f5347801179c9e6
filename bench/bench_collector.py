"""The garbage collector's full pass in each long-running process, before and after its start-up objects
are frozen (:func:`taskflight_common.runtime.freeze_startup_heap`).

Each process kind is built in a fresh interpreter as its main function builds it (the model: a Sitl; the
companion: a QuadNode with its executive layer, mission service and control server; the ground service:
its FastAPI app on a SQLite file), then a full collection is timed (median of 7, each after 64 MB of other
memory traffic, as in a running process whose caches no longer hold the heap) before and after the
freeze. A full collection stops every thread of the process: the companion's setpoint stream included.

    python -m bench.bench_collector
"""

from __future__ import annotations

import json
import logging
import statistics
import subprocess
import sys
import tempfile

from bench.common import machine, table

KINDS = ("model", "companion", "ground")

_CHILD = r'''
import gc, json, statistics, sys, tempfile, time
from pathlib import Path
kind = sys.argv[1]
tmp = Path(tempfile.mkdtemp())
keep = []
if kind == "model":
    from autopilot_model.sitl import Sitl
    keep.append(Sitl(instance=40, urls=["udpin:127.0.0.1:0"], speedup=1.0, state_dir=tmp, persist=False))
elif kind == "companion":
    from companion.builder import CompanionConfig, build_companion
    from companion.tst.platform import bundled_platform
    companion = build_companion(CompanionConfig("udpout:127.0.0.1:9", rate_hz=20.0,
                                                behavior_log=tmp / "b.jsonl",
                                                platform=bundled_platform("indoor"), control_port=0))
    keep += [companion, companion.control_server()]
else:
    from groundstation.app import create_app
    from groundstation.auth import Tokens
    from groundstation.service import GroundService
    service = GroundService(str(tmp / "g.sqlite"), Tokens.generate(), team_url="udp://127.0.0.1:47999")
    keep += [service, create_app(service, 0.1)]
from taskflight_common.runtime import freeze_startup_heap
def full_ms():
    ts = []
    for _ in range(7):
        churn = bytearray(64 << 20)  # a running process's other work: the caches no longer hold the heap
        churn[::4096] = b"x" * len(churn[::4096])
        del churn
        t = time.perf_counter(); gc.collect(); ts.append((time.perf_counter() - t) * 1e3)
    return statistics.median(ts)
gc.collect()
objects = len(gc.get_objects())
before = full_ms()
frozen = freeze_startup_heap(kind)
after = full_ms()
print(json.dumps({"objects": objects, "before_ms": before, "frozen": frozen, "after_ms": after}))
'''


def measure(kind: str) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", _CHILD, kind], capture_output=True, text=True, timeout=300,
                         cwd=tempfile.gettempdir())
    if out.returncode != 0:
        raise RuntimeError(f"{kind}: {out.stderr.strip().splitlines()[-1] if out.stderr else out.returncode}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    logging.basicConfig(level=logging.WARNING)
    rows = []
    for kind in KINDS:
        runs = [measure(kind) for _ in range(3)]
        rows.append((kind, int(runs[0]["objects"]),
                     f"{statistics.median(r['before_ms'] for r in runs):.1f}",
                     f"{statistics.median(r['after_ms'] for r in runs):.2f}"))
    print(f"full garbage collection per process kind (median of 3 processes x 7 passes); {machine()}")
    print(table(("process", "tracked objects at start-up", "full pass ms", "frozen: full pass ms"), rows))


if __name__ == "__main__":
    main()
