"""Helpers shared by the MAVLink integration tests (no tests here): a SITL subprocess, free ports.

The model runs in its own process (``python -m autopilot_model.sitl``), lockstep at a fixed speedup,
so the clients under test talk to it over real loopback sockets exactly as they would to ArduPilot.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    s = socket.socket(socket.AF_INET, kind)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


class SitlProcess:
    """``python -m autopilot_model.sitl`` in a subprocess; waits for its READY line."""

    def __init__(self, urls: Sequence[str], state_dir: Path, speedup: float = 10.0,
                 extra: Sequence[str] = (), timeout_s: float = 60.0) -> None:
        args = [sys.executable, "-m", "autopilot_model.sitl", "--state-dir", str(state_dir),
                "--speedup", str(speedup)]
        for u in urls:
            args += ["--mavlink", u]
        args += list(extra)
        env = dict(os.environ)
        env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
        self.proc = subprocess.Popen(args, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT,
                                     text=True)
        end = time.monotonic() + timeout_s
        self.ready = ""
        assert self.proc.stdout is not None
        while time.monotonic() < end:
            line = self.proc.stdout.readline()
            if not line:
                break
            if line.startswith("READY"):
                self.ready = line.strip()
                return
        self.stop()
        raise RuntimeError(f"SITL did not start: {self.ready or 'no READY line'}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)


def wait_for(pred: Callable[[], Any], timeout_s: float, what: str,
             poll: Callable[[], None] | None = None) -> Any:
    """Call ``poll`` and test ``pred`` until it is truthy or the wall deadline passes."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if poll is not None:
            poll()
        r = pred()
        if r:
            return r
        if poll is None:
            time.sleep(0.01)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
