"""taskflight_common.runtime.die_with_parent: a child of ``taskflight up`` stops when its parent is gone."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from taskflight_common.runtime import PARENT_ENV

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
CHILD = ("import os, time; from taskflight_common.runtime import PARENT_ENV, die_with_parent; "
         "armed = die_with_parent(); print(armed, PARENT_ENV in os.environ, flush=True); time.sleep(20)")


def _run(parent: str | None) -> subprocess.Popen[str]:
    env = {k: v for k, v in os.environ.items() if k != PARENT_ENV}
    env["PYTHONPATH"] = str(ROOT)
    if parent is not None:
        env[PARENT_ENV] = parent
    return subprocess.Popen([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True, env=env)


def test_a_child_whose_parent_is_already_gone_stops_at_once() -> None:
    p = _run("1")  # not our parent: as if taskflight up had died before the request took effect
    assert p.wait(15) == -signal.SIGTERM
    assert p.stdout is not None and p.stdout.read() == ""  # it never went on
    p.stdout.close()


def test_a_child_of_a_living_parent_goes_on_and_hides_the_variable_from_its_own_children() -> None:
    for parent, expect in ((str(os.getpid()), "True False"), (None, "False False")):
        p = _run(parent)
        try:
            assert p.stdout is not None and p.stdout.readline().strip() == expect
            assert p.poll() is None  # still running
        finally:
            p.kill()
            p.wait(10)
            p.stdout.close()
