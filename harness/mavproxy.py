"""MAVProxy, the ground station many operators fly with, on the bundled model (no tests here).

* :func:`mavproxy_command`: how to run this environment's ``mavproxy.py`` (a skip when it is missing);
* :class:`Lines`: a child's stdout lines, waited on with deadlines;
* :class:`MavProxy`: ``mavproxy.py --master=tcp:...`` as a child process, typed into when interactive;
* :func:`mavproxy_on_model`: a model on a TCP port (MAVProxy's) and a UDP port (a pymavlink
  :class:`~harness.observer.Gcs`'s), MAVProxy connected; all closed after.
"""

from __future__ import annotations

import contextlib
import os
import queue
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from harness import ROOT
from harness.model import SitlProcess
from harness.observer import Gcs
from taskflight_common.ports import free_ports


def mavproxy_command() -> list[str]:
    """``[python, mavproxy.py]`` of this environment; skips the test when MAVProxy is not installed."""
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


class MavProxy:
    """MAVProxy on ``tcp:127.0.0.1:<tcp>`` with its state in ``d``; its output in :attr:`out`. Interactive:
    commands are typed on its stdin (:meth:`type`); else ``--non-interactive`` with no stdin."""

    def __init__(self, tcp: int, d: Path, *, interactive: bool = True) -> None:
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        args = [*mavproxy_command(), f"--master=tcp:127.0.0.1:{tcp}"]
        if not interactive:
            args.append("--non-interactive")
        self.proc = subprocess.Popen([*args, f"--state-basedir={d}"], cwd=d, env=env,
                                     stdin=subprocess.PIPE if interactive else subprocess.DEVNULL,
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.out = Lines(self.proc)

    def type(self, line: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()

    def close(self) -> None:
        if self.proc.stdin is not None:
            with contextlib.suppress(BrokenPipeError, OSError):
                self.type("exit")
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


@contextmanager
def mavproxy_on_model(d: Path, model_speedup: float, *, interactive: bool = True, persist: bool = False,
                      **gcs_options: Any) -> Iterator[tuple[MavProxy, Gcs]]:
    """The model at ``model_speedup`` (its state in ``d / "state"``; parameters not kept unless ``persist``)
    with MAVProxy on its TCP port and a :class:`Gcs` (``gcs_options``) on its UDP port; all closed after."""
    mavproxy_command()  # skip before starting anything when MAVProxy is missing
    tcp, udp = free_ports(1, socket.SOCK_STREAM)[0], free_ports(1, socket.SOCK_DGRAM)[0]  # each its own
    sitl = SitlProcess([f"tcpin:127.0.0.1:{tcp}", f"udpin:127.0.0.1:{udp}"], d / "state",
                       speedup=model_speedup, extra=[] if persist else ["--no-persist"])
    try:
        gcs = Gcs(udp, **gcs_options)
        try:
            mp = MavProxy(tcp, d, interactive=interactive)
            try:
                yield mp, gcs
            finally:
                mp.close()
        finally:
            gcs.close()
    finally:
        sitl.stop()
