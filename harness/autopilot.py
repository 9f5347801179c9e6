"""The two autopilots the companion is proven against, started the same way (no tests here).

* ``model``: the bundled autopilot model (:class:`harness.model.SitlProcess`), listening on UDP;
* ``arducopter``: ArduPilot's own copter SITL (:mod:`harness.arducopter`); its SERIAL0 and SERIAL1 send
  UDP to ports we listen on.

:func:`start_autopilot` returns an :class:`Autopilot`: the URL the companion connects to, a
:class:`~harness.wire_tap.WireTap` between the companion and the autopilot that decodes what the
companion puts on the wire, and a pymavlink :class:`~harness.observer.Gcs` (system 255) on another
link. Tests that need ArduCopter use :data:`requires_arducopter` (a skip saying why).
"""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from harness.arducopter import ArduCopterSitl, arducopter_missing, requires_arducopter
from harness.model import SitlProcess
from harness.observer import Gcs
from harness.timing import wait_for
from harness.wire_tap import WireTap
from taskflight_common.ports import free_ports

#: the autopilots a parametrised test flies: ArduCopter is skipped, saying why, without the binary
AUTOPILOTS = [pytest.param("model", id="model"),
              pytest.param("arducopter", id="arducopter", marks=requires_arducopter)]

class Autopilot:
    """One autopilot under test with its wire tap and ground station (see module docstring)."""

    def __init__(self, kind: str, state_dir: Path, speedup: float, record: str | None = None) -> None:
        self.kind = kind
        self.speedup = speedup
        self.process: SitlProcess | ArduCopterSitl
        if kind == "model":
            port = free_ports(1, socket.SOCK_DGRAM)[0]
            self.process = SitlProcess([f"udpin:127.0.0.1:{port}"], state_dir, speedup=speedup,
                                       extra=["--no-persist"])
            self.tap = WireTap(port, record=record)
            self.companion_url = f"udpout:127.0.0.1:{self.tap.port}"
            self.gcs = Gcs(port, speedup, background=True)
        elif kind == "arducopter":
            missing = arducopter_missing()
            if missing:
                pytest.skip(missing)
            companion_port, gcs_port = free_ports(2, socket.SOCK_DGRAM)
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
