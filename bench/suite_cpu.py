"""Bench: where the test suite's time goes, test by test: wall seconds and the machine's CPU seconds.

A pytest plugin and a summary. Run the part of the suite you want with the plugin, on an otherwise idle
machine (the CPU is the whole machine's, from ``/proc/stat``, so anything else running is counted too)::

    SUITE_CPU_OUT=/tmp/suite.tsv python -m pytest -q -p no:cacheprovider -p bench.suite_cpu -m integration
    python -m bench.suite_cpu /tmp/suite.tsv --top 20

The plugin appends one line per test (node id, wall s, CPU s) to ``SUITE_CPU_OUT``; a module-scoped rig's
start-up is counted in its module's first test. The summary prints the totals and the test files that cost
the most CPU.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from bench.common import table


def machine_cpu_s() -> float:
    """CPU seconds the whole machine has spent busy since boot (user, nice, system, irq, softirq, steal)."""
    with open("/proc/stat") as f:
        v = [int(x) for x in f.readline().split()[1:]]
    return (v[0] + v[1] + v[2] + v[5] + v[6] + v[7]) / os.sysconf("SC_CLK_TCK")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: Any, nextitem: Any) -> Iterator[None]:
    c0, t0 = machine_cpu_s(), time.monotonic()
    yield
    c1, t1 = machine_cpu_s(), time.monotonic()
    with open(os.environ.get("SUITE_CPU_OUT", "suite_cpu.tsv"), "a") as f:
        f.write(f"{item.nodeid}\t{t1 - t0:.2f}\t{c1 - c0:.2f}\n")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("tsv", type=Path, help="what the plugin wrote")
    p.add_argument("--top", type=int, default=20, help="test files listed")
    args = p.parse_args()
    files: dict[str, list[float]] = defaultdict(lambda: [0, 0.0, 0.0])
    for line in args.tsv.read_text().splitlines():
        node, wall, cpu = line.rsplit("\t", 2)
        f = files[node.split("::", 1)[0]]
        f[0] += 1
        f[1] += float(wall)
        f[2] += float(cpu)
    n = sum(int(v[0]) for v in files.values())
    wall = sum(v[1] for v in files.values())
    cpu = sum(v[2] for v in files.values())
    print(f"{n} tests, {wall:.0f} s of wall time, {cpu:.0f} s of the machine's CPU "
          f"({cpu / max(wall, 1e-9):.2f} cores)")
    rows = [[name, int(v[0]), f"{v[1]:.0f}", f"{v[2]:.0f}", f"{100 * v[2] / max(cpu, 1e-9):.1f}"]
            for name, v in sorted(files.items(), key=lambda kv: -kv[1][2])[:args.top]]
    print(table(["test file", "tests", "wall s", "CPU s", "% of the CPU"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
