"""The two autopilots the companion is proven against, started the same way (no tests here).

* ``model``: the bundled autopilot model (:class:`mavlink_support.SitlProcess`), listening on UDP;
* ``arducopter``: ArduPilot's own copter SITL, the binary named by ``TASKFLIGHT_ARDUCOPTER`` (built
  by hand outside the project, see ``../shared/ardupilot/README.md``), run in a temporary folder with
  ArduPilot's default ``copter.parm``; its SERIAL0 and SERIAL1 send UDP to ports we listen on.

:func:`start_autopilot` returns an :class:`Autopilot`: the URL the companion connects to, a
:class:`~companion_support.WireTap` between the companion and the autopilot that decodes what the
companion puts on the wire, and a pymavlink :class:`~mavlink_support.Gcs` (system 255) on another
link. Tests that need ArduCopter use :data:`requires_arducopter` (a skip saying why).
"""

from __future__ import annotations

import os
import socket
import subprocess
import tempfile
from pathlib import Path

import pytest
from companion_support import WireTap
from mavlink_support import ROOT, Gcs, SitlProcess, free_port, free_ports, wait_for

from taskflight.sitlproc import stop_child
from taskflight_common.ports import port_free

#: the ArduCopter SITL binary, or None
ARDUCOPTER = os.environ.get("TASKFLIGHT_ARDUCOPTER") or None
#: ArduPilot's default parameters for the + quad (shared/ardupilot/copter.parm beside the project)
COPTER_PARM = Path(os.environ.get("TASKFLIGHT_ARDUCOPTER_DEFAULTS",
                                  ROOT.parent / "shared" / "ardupilot" / "copter.parm"))
HOME = "-35.363261,149.165230,584,353"


def arducopter_missing() -> str | None:
    """Why ArduCopter SITL cannot run here (None when it can)."""
    if ARDUCOPTER is None:
        return "TASKFLIGHT_ARDUCOPTER is not set (ArduPilot's copter SITL binary; see ../shared/ardupilot)"
    if not os.access(ARDUCOPTER, os.X_OK):
        return f"TASKFLIGHT_ARDUCOPTER={ARDUCOPTER} is not an executable file"
    if not COPTER_PARM.is_file():
        return f"ArduPilot's copter.parm not found at {COPTER_PARM} (set TASKFLIGHT_ARDUCOPTER_DEFAULTS)"
    return None


requires_arducopter = pytest.mark.skipif(arducopter_missing() is not None,
                                         reason=arducopter_missing() or "")

#: the autopilots a parametrised test flies: ArduCopter is skipped, saying why, without the binary
AUTOPILOTS = [pytest.param("model", id="model"),
              pytest.param("arducopter", id="arducopter", marks=requires_arducopter)]

_instances = iter(range(10, 60))


def _instance_free(i: int) -> bool:
    """Instance ``i``'s own ports (RC input UDP 5501+10i, SERIAL0 TCP 5760+10i) are free here: another
    test process (or agent) running SITL at the same time picks another one."""
    return all(port_free(kind, port) for kind, port in ((socket.SOCK_DGRAM, 5501 + 10 * i),
                                                          (socket.SOCK_STREAM, 5760 + 10 * i)))


def _next_instance() -> int:
    for i in _instances:
        if _instance_free(i):
            return i
    raise RuntimeError("no free ArduCopter SITL instance number in 10..59")


class ArduCopterSitl:
    """ArduPilot's copter SITL in a temporary folder; SERIALn sends UDP to ``ports[n]`` on loopback."""

    def __init__(self, ports: list[int], speedup: float, instance: int | None = None,
                 home: str = HOME) -> None:
        assert ARDUCOPTER is not None
        self.dir = tempfile.TemporaryDirectory(prefix="arducopter-")
        self.instance = _next_instance() if instance is None else instance
        args = [ARDUCOPTER, "--model", "+", "--speedup", f"{speedup:g}", "--defaults", str(COPTER_PARM),
                f"-I{self.instance}", "--home", home, "-w"]
        for n, port in enumerate(ports):
            args += [f"--serial{n}", f"udpclient:127.0.0.1:{port}"]
        self.log_path = Path(self.dir.name) / "arducopter.log"
        self._log = open(self.log_path, "w")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(args, cwd=self.dir.name, stdout=self._log, stderr=subprocess.STDOUT)

    def stop(self) -> None:
        stop_child(self.proc, name="ArduCopter SITL")
        self._log.close()
        self.dir.cleanup()


class Autopilot:
    """One autopilot under test with its wire tap and ground station (see module docstring)."""

    def __init__(self, kind: str, state_dir: Path, speedup: float, record: str | None = None) -> None:
        self.kind = kind
        self.speedup = speedup
        self.process: SitlProcess | ArduCopterSitl
        if kind == "model":
            port = free_port()
            self.process = SitlProcess([f"udpin:127.0.0.1:{port}"], state_dir, speedup=speedup,
                                       extra=["--no-persist"])
            self.tap = WireTap(port, record=record)
            self.companion_url = f"udpout:127.0.0.1:{self.tap.port}"
            self.gcs = Gcs(port, speedup, background=True)
        elif kind == "arducopter":
            missing = arducopter_missing()
            if missing:
                pytest.skip(missing)
            companion_port, gcs_port = free_ports(2)
            self.tap = WireTap(companion_port, record=record, companion_side="back", avoid=(gcs_port,))
            self.companion_url = f"udpin:127.0.0.1:{companion_port}"
            self.gcs = Gcs(0, speedup, url=f"udpin:127.0.0.1:{gcs_port}", background=True)
            self.process = ArduCopterSitl([self.tap.port, gcs_port], speedup)
        else:
            raise ValueError(f"unknown autopilot {kind!r}")
        wait_for(lambda: self.gcs.last.get("HEARTBEAT") is not None, 30, f"{kind}: the first heartbeat")
        self.gcs.request_streams(10)

    def describe(self) -> str:
        """What to look at when a wait on this autopilot times out."""
        out = f"{self.kind}: tap relayed to {self.tap.back.getpeername()} from {self.tap._client}, " \
              f"companion sent {dict(self.tap.sent)}"
        if isinstance(self.process, ArduCopterSitl) and self.process.log_path.exists():
            tail = self.process.log_path.read_text(errors="replace").splitlines()[-8:]
            out += "; ArduCopter log: " + " | ".join(tail)
        return out

    def close(self) -> None:
        self.gcs.close()
        self.tap.close()
        self.process.stop()


def start_autopilot(kind: str, state_dir: Path, speedup: float, record: str | None = None) -> Autopilot:
    """The autopilot ``kind`` ("model" or "arducopter") with its tap (timing ``record`` messages) and GCS."""
    return Autopilot(kind, state_dir, speedup, record)
