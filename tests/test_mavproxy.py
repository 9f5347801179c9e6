"""MAVProxy (pip package), run non-interactively over TCP, connects and sees the mode and arming state.

The mode and arming are changed by a second ground station (pymavlink over UDP), so what is checked
is MAVProxy's own view of the vehicle: its console lines for the detected vehicle, the mode, ARMED,
DISARMED and the parameter download.
"""

from __future__ import annotations

import os
import queue
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from harness import ROOT
from harness.model import SitlProcess
from harness.observer import Gcs, M
from taskflight_common.ports import free_ports

pytestmark = pytest.mark.integration


def _mavproxy() -> list[str]:
    exe = shutil.which("mavproxy.py") or str(Path(sys.executable).parent / "mavproxy.py")
    if not Path(exe).exists():
        pytest.skip("MAVProxy is not installed")
    return [sys.executable, exe]


class Lines:
    """A subprocess's stdout lines, read by a thread, waited on with deadlines."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.q: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, args=(proc,), daemon=True).start()

    def _read(self, proc: subprocess.Popen[str]) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            self.q.put(line.rstrip())

    def wait(self, text: str, timeout_s: float) -> str:
        for line in self.seen:
            if text in line:
                return line
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            try:
                line = self.q.get(timeout=0.05)
            except queue.Empty:
                continue
            self.seen.append(line)
            if text in line:
                return line
        raise AssertionError(f"MAVProxy never printed {text!r}; last lines: {self.seen[-15:]}")


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Lines, Gcs]]:
    tcp, udp = free_ports(1, socket.SOCK_STREAM)[0], free_ports(1, socket.SOCK_DGRAM)[0]  # each its own
    d = tmp_path_factory.mktemp("mavproxy")
    sitl = SitlProcess([f"tcpin:127.0.0.1:{tcp}", f"udpin:127.0.0.1:{udp}"], d / "state", speedup=10)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([*_mavproxy(), f"--master=tcp:127.0.0.1:{tcp}", "--non-interactive",
                             f"--state-basedir={d}"],
                            cwd=d, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    gcs = Gcs(udp)
    try:
        yield Lines(proc), gcs
    finally:
        gcs.close()
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
        sitl.stop()


def test_mavproxy_sees_vehicle_mode_and_arming(setup: tuple[Lines, Gcs]) -> None:
    m = M
    out, gcs = setup
    out.wait("Detected vehicle 1:1", 30)
    out.wait("Mode STABILIZE", 20)
    out.wait("Received", 30)  # "Received N parameters": the paced parameter list went through
    gcs.wait_prearm(30)
    assert gcs.set_mode(4) == m.MAV_RESULT_ACCEPTED
    out.wait("Mode GUIDED", 10)
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1) == m.MAV_RESULT_ACCEPTED
    out.wait("ARMED", 10)
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 0) == m.MAV_RESULT_ACCEPTED
    out.wait("DISARMED", 10)
    assert not any("fence breach" in line for line in out.seen)
