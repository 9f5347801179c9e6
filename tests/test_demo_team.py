"""The team demo (``scripts/demo`` = ``taskflight demo-team``) runs to its report.

Three vehicles started as ``taskflight up`` starts them, on a free block of instance numbers; vehicle 1
flies the scan-and-search mission, the team a visit and a patrol line; the demo exits 0 with a report
naming what each vehicle did, each task's final state and holder, and each vehicle's flight figures.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from harness import ROOT
from harness.up import child_env, processes_mentioning
from taskflight.up import ground_available
from taskflight_common.ports import free_base

pytestmark = pytest.mark.integration


def test_the_team_demo_flies_its_scenario_and_reports(tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "taskflight.cli", "demo-team", "--speedup", "3", "--patrol", "20",
            "--base-instance", str(free_base(3)), "--state-dir", str(tmp_path / "demo")]
    if not ground_available():
        argv.append("--no-ground")
    run = subprocess.run(argv, capture_output=True, text=True, timeout=400, cwd=ROOT, env=child_env())
    out = run.stdout
    assert run.returncode == 0, out + run.stderr
    assert "vehicle 1: mission scan-and-search-outdoor: succeeded" in out
    tasks = dict(re.findall(r"^\s+\d+ (visit|patrol_line)\s+\S+\s+(\w+)\s+"
                            r"held by vehicle [23](?:, vehicle [23])*$",  # the team may hand a task on
                            out, re.M))
    assert tasks == {"visit": "done", "patrol_line": "cancelled"}, out
    flown = re.findall(r"flight time ([\d.]+) s, (\d+) m flown; tracking h rms ([\d.]+) m", out)
    assert len(flown) == 3 and all(float(t) > 5 and float(h) < 1.0 for t, _d, h in flown), out
    assert processes_mentioning(str(tmp_path)) == []
