"""ArduPilot's own copter SITL for the differential tests and benches: the binary named by
``TASKFLIGHT_ARDUCOPTER`` (built by hand outside the project, see ``../shared/ardupilot/README.md``), run
in a temporary folder with ArduPilot's default ``copter.parm``, on an instance number whose ports are
free. Tests that need it use :data:`requires_arducopter` (a skip saying why)."""

from __future__ import annotations

import os
import socket
import subprocess
import tempfile
from pathlib import Path

import pytest

from harness import ROOT
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
                 home: str = HOME, params: dict[str, float] | None = None) -> None:
        """``params``: more defaults after ``copter.parm`` (a second defaults file: parameters that take
        effect at boot only, such as RNGFND1_TYPE 100 for the SITL range finder, need no reboot)."""
        assert ARDUCOPTER is not None
        self.dir = tempfile.TemporaryDirectory(prefix="arducopter-")
        self.instance = _next_instance() if instance is None else instance
        defaults = str(COPTER_PARM)
        if params:
            extra = Path(self.dir.name) / "extra.parm"
            extra.write_text("".join(f"{name} {value:g}\n" for name, value in params.items()))
            defaults += f",{extra}"
        args = [ARDUCOPTER, "--model", "+", "--speedup", f"{speedup:g}", "--defaults", defaults,
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


