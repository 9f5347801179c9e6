"""The bundled autopilot model in its own process, as the tests and benches talk to it.

* :class:`SitlProcess`: ``python -m autopilot_model.sitl`` lockstep at a fixed speedup, so the clients
  under test talk to it over real loopback sockets exactly as they would to ArduPilot;
* :func:`sitl_and_gcs`: one, with a :class:`~harness.observer.Gcs` that has heard the vehicle;
* :func:`model_in_process`: the model in the test's own process (:class:`~autopilot_model.sitl.Sitl`,
  stepped by the test), its estimate converged, on the ground ready to arm or airborne in GUIDED.

A fleet of models in one process is :mod:`harness.fleet`.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from harness.observer import Gcs
from harness.timing import SPEEDUP
from taskflight.sitlproc import ModelProcess
from taskflight_common.ports import free_ports

if TYPE_CHECKING:
    from autopilot_model.sitl import Sitl


class SitlProcess(ModelProcess):
    """``python -m autopilot_model.sitl`` in a subprocess at a fixed speedup; started when built (READY)."""

    def __init__(self, urls: Sequence[str], state_dir: Path, speedup: float = SPEEDUP,
                 extra: Sequence[str] = (), timeout_s: float = 60.0) -> None:
        args = ["--state-dir", str(state_dir), "--speedup", str(speedup)]
        for u in urls:
            args += ["--mavlink", u]
        super().__init__([*args, *extra], name="model SITL")
        self.start(timeout_s)


@contextmanager
def sitl_and_gcs(state_dir: Path, speedup: float = SPEEDUP, extra: Sequence[str] = (),
                 **gcs_options: Any) -> Iterator[Gcs]:
    """A SITL process on a free UDP port and a :class:`Gcs` that has heard the vehicle; both closed after."""
    port = free_ports(1, socket.SOCK_DGRAM)[0]
    sitl = SitlProcess([f"udpin:127.0.0.1:{port}"], state_dir, speedup=speedup, extra=extra)
    try:
        gcs = Gcs(port, speedup, **gcs_options)
        try:
            gcs.wait(lambda: (m := gcs.last.get("HEARTBEAT")) is not None and m.get_srcSystem() == 1, 20,
                     "the vehicle's first heartbeat")
            yield gcs
        finally:
            gcs.close()
    finally:
        sitl.stop()


@contextmanager
def model_in_process(state_dir: Path, takeoff_m: float | None = None) -> Iterator[Sitl]:
    """The model in this process on a free UDP port (parameters not kept), its estimator converged; then
    either on the ground with the pre-arm checks passing, or (``takeoff_m``) taken off in GUIDED to that
    height and settled for 2 s. Closed after."""
    from autopilot_model.modules.flight_modes import GUIDED  # the model itself only where it runs here
    from autopilot_model.sitl import Sitl

    port = free_ports(1, socket.SOCK_DGRAM)[0]
    s = Sitl(urls=[f"udpin:127.0.0.1:{port}"], state_dir=state_dir, persist=False)
    try:
        v = s.vehicle
        assert v.wait_estimator(10.0)
        if takeoff_m is None:
            assert v.run_until(lambda: not v.nav.prearm_failures(), 60.0)
        else:
            assert s.modes.set_mode(GUIDED)[0]
            assert v.nav.arm()[0] and v.nav.takeoff(takeoff_m)[0]
            assert v.run_until(lambda: v.world.x[2] < -(takeoff_m - 0.2), 30.0)
            v.run_for(2.0)
        yield s
    finally:
        s.close()
