"""``taskflight up`` as a subprocess for the tests and the bench.

:class:`UpProcess` starts ``python -m taskflight.cli up ...`` on a free block of instance numbers (its
MAVLink ports, as :mod:`fleet_support` picks them), reads its output in a thread, and parses the summary
it prints after ``READY``: the child PIDs, each vehicle's MAVLink TCP port and companion URL, the team
link, the ground URL and tokens.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from harness import ROOT
from harness.ground import OBSERVER, OPERATOR, OPERATOR2, GroundRig, _Api
from harness.observer import Gcs
from taskflight_common.ports import free_base, free_ports


@dataclass
class Summary:
    pids: dict[str, int] = field(default_factory=dict)
    tcp: list[int] = field(default_factory=list)
    companions: list[str] = field(default_factory=list)
    team: str = ""
    ground: str | None = None
    operator: str | None = None
    observer: str | None = None


def child_env() -> dict[str, str]:
    """The environment for ``python -m taskflight.cli`` children: this checkout first on the path."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env["PYTHONUNBUFFERED"] = "1"
    return env


class UpProcess:
    """``taskflight up ARGS`` in a child process; :meth:`wait_ready` parses its summary. ``command``: another
    command that prints the same summary (``demo-team``); ``env``: the child's environment (child_env())."""

    def __init__(self, args: Sequence[str], state_dir: Path, command: str = "up",
                 env: dict[str, str] | None = None) -> None:
        env = child_env() if env is None else env
        self.argv = [sys.executable, "-m", "taskflight.cli", command, "--state-dir", str(state_dir), *args]
        self.proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     env=env, cwd=ROOT, stdin=subprocess.DEVNULL)
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._cond:
                self.lines.append(line.rstrip("\n"))
                self._cond.notify_all()
        with self._cond:
            self._cond.notify_all()

    @property
    def output(self) -> str:
        with self._cond:
            return "\n".join(self.lines)

    def wait_line(self, prefix: str, timeout_s: float) -> str:
        """The first output line starting with ``prefix`` (AssertionError with the output if none in time
        or if the process exits first)."""
        end = time.monotonic() + timeout_s
        with self._cond:
            while True:
                for line in self.lines:
                    if line.startswith(prefix):
                        return line
                left = end - time.monotonic()
                if left <= 0 or (self.proc.poll() is not None and not self._reader.is_alive()):
                    out = "\n".join(self.lines)
                    raise AssertionError(f"no line {prefix!r} from taskflight up in {timeout_s:.0f} s "
                                         f"(status {self.proc.poll()}); its output:\n{out}")
                self._cond.wait(min(left, 0.5))

    def wait_ready(self, timeout_s: float) -> Summary:
        self.wait_line("READY", timeout_s)
        self.wait_line("logs:", 10.0)
        s = Summary()
        for line in self.lines:
            if m := re.match(r"pids: (?:fleet (\d+)|arducopter ([\d ]+)); companions ([\d ]+)"
                             r"(?:; ground (\d+))?", line):
                if m.group(1):
                    s.pids["fleet"] = int(m.group(1))
                for i, p in enumerate((m.group(2) or "").split()):  # an ArduCopter SITL per vehicle
                    s.pids[f"arducopter{i + 1}"] = int(p)
                for i, p in enumerate(m.group(3).split()):
                    s.pids[f"companion{i + 1}"] = int(p)
                if m.group(4):
                    s.pids["ground"] = int(m.group(4))
            elif m := re.match(r"vehicle \d+: sysid \d+  MAVLink tcp:[\d.]+:(\d+) .* companion (\S+)", line):
                s.tcp.append(int(m.group(1)))
                s.companions.append(m.group(2))
            elif line.startswith("team link: "):
                s.team = line.split(": ", 1)[1]
            elif m := re.match(r"ground service: (\S+)", line):
                s.ground = m.group(1)
            elif line.startswith("operator token: "):
                s.operator = line.split(": ", 1)[1]
            elif line.startswith("observer token: "):
                s.observer = line.split(": ", 1)[1]
        return s

    def interrupt(self, timeout_s: float = 60.0) -> int:
        """SIGINT (Ctrl-C) and wait for the exit status."""
        self.proc.send_signal(signal.SIGINT)
        return self.proc.wait(timeout_s)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(60)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        self._reader.join(5)


def alive(pid: int) -> bool:
    """The process exists and is not a zombie (/proc)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def processes_mentioning(text: str) -> list[int]:
    """PIDs of live processes whose command line contains ``text`` (e.g. a test's state directory)."""
    out = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode("utf-8", "replace")
        except OSError:
            continue
        if text in cmd and alive(int(d)):
            out.append(int(d))
    return out


class UpRig(GroundRig):
    """The fleet exactly as an operator starts it: ``taskflight up --vehicles N`` (models, companions on one
    team link, the ground service with the tests' tokens), plus a pymavlink ground station per vehicle on
    its model's UDP port (positions read from the autopilots over MAVLink). Offers GroundRig's views
    (``ground.url``, ``ground.http()``, ``vehicles()``, ``tasks()``, ``position(i)``, ``tracks``)."""

    def __init__(self, tmp: Path, n: int = 3, speedup: float = 3.0, scenario: Path | None = None,
                 extra: Sequence[str] = ()) -> None:
        self.tmp, self.n, self.speedup = tmp, n, speedup
        self.base = free_base(n)
        tokens = tmp / "tokens.yaml"
        tokens.write_text(f"operator: [{OPERATOR}, {OPERATOR2}]\nobserver: [{OBSERVER}]\n")
        tokens.chmod(0o600)
        self.companions = []
        self.gcs: list[Gcs] = []
        port = free_ports(1, socket.SOCK_STREAM)[0]
        extra = list(extra)
        if "--ready-timeout" not in extra:
            extra += ["--ready-timeout", "170"]  # a loaded machine starts slowly
        ready_s = float(extra[extra.index("--ready-timeout") + 1]) + 10  # up's own time-out and a little
        self.up = UpProcess(["--vehicles", str(n), "--speedup", str(speedup), "--base-instance",
                             str(self.base), "--ground-port", str(port), "--tokens", str(tokens),
                             "--no-persist", *(["--scenario", str(scenario)] if scenario else []), *extra],
                            tmp / "state")
        try:
            summary = self.up.wait_ready(ready_s)
            self.summary = summary
            assert summary.ground, self.up.output
            self.ground = _UpGround(summary.ground)
            self._observe()
        except BaseException:
            self.close()
            raise

    def report(self, log_lines: int = 15) -> str:
        """What a failed wait needs to say: the board, each vehicle as the service sees it, and the end of
        every child's log (``taskflight up`` writes them to ``<state-dir>/logs``)."""
        parts = []
        try:
            parts.append("tasks: " + "; ".join(f"{t['id']} {t['kind']} {t['state']} holder {t['holder']}"
                                              for t in self.tasks().values()))
            keys = ("member_status", "team_state", "task", "claims", "mission", "health", "mode", "age_s")
            parts.append("vehicles: " + "; ".join(f"{v['id']} " + " ".join(f"{k}={v.get(k)}" for k in keys)
                                                  for v in self.vehicles().values()))
        except Exception as exc:  # the service itself may be what failed
            parts.append(f"ground service not answering: {exc!r}")
        for log in sorted((self.tmp / "state" / "logs").glob("*.log")):
            tail = log.read_text(errors="replace").splitlines()[-log_lines:]
            parts.append(f"--- end of {log.name}:\n" + "\n".join(tail))
        return "\n".join(parts)

    def close(self) -> None:
        if hasattr(self, "_stop"):
            self._stop.set()
        for g in self.gcs:
            g.close()
        self.up.close()


class _UpGround(_Api):
    def __init__(self, url: str) -> None:
        self.url = url
