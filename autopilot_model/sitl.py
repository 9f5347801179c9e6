"""Software-in-the-loop wiring: one vehicle + MAVLink endpoint + flight modes + missions + failsafes.

:class:`Sitl` is what ``taskflight autopilot`` runs, and what the integration tests start (in a
subprocess, through ``python -m autopilot_model.sitl``). It assembles:

* the :class:`~autopilot_model.vehicle.Vehicle`,
* :class:`~autopilot_model.modules.flight_modes.FlightModes` (``flight_modes.update``, navigation group),
* missions (store, runner) and failsafes (safety),
* the :class:`~autopilot_model.mavlink.endpoint.MavlinkEndpoint` with every protocol piece, built by
  :func:`autopilot_model.mavlink.wiring.vehicle_link` (``mavlink.poll`` as an event function,
  ``mavlink.telemetry`` in the telemetry group, seed 002),
* parameters persisted per instance (``<state-dir>/instance<N>/params.json``), loaded before any
  piece declares its parameters (a saved value is applied as its parameter is declared, so every piece
  starts with the saved value, as ArduCopter's ``AP_Param::load_all`` does before the libraries start).

Defaults for instance N follow ArduPilot SITL: ``tcpin:0.0.0.0:5760+10N``, plus one UDP endpoint
``udpin:0.0.0.0:14550+10N`` -- the port ground stations and companions conventionally use, in the
*listening* role so that any number of clients can connect by sending first (pymavlink
``udpout:HOST:14550``, MAVSDK ``udpout://HOST:14550``, MAVProxy ``--master=udpout:HOST:14550``); pass
``--mavlink udpout:HOST:PORT`` to push to a ground station that listens instead. The system id is
N+1 (parameter MAV_SYSID) so several vehicles run side by side.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from autopilot_model.demo import add_model_arguments
from taskflight_common.cliargs import join_signed_values
from taskflight_common.ports import model_ports
from taskflight_common.runtime import freeze_startup_heap, setup_logging, stop_on_signals
from taskflight_common.yamlio import ConfigError

log = logging.getLogger(__name__)

def default_urls(instance: int) -> list[str]:
    """ArduPilot SITL's listening endpoints of ``instance`` (:func:`taskflight_common.ports.model_ports`)."""
    tcp, udp = model_ports(instance)
    return [f"tcpin:0.0.0.0:{tcp}", f"udpin:0.0.0.0:{udp}"]


def default_state_dir() -> Path:
    return Path(os.environ.get("TASKFLIGHT_STATE", Path.home() / ".taskflight"))


class Sitl:
    """One simulated ArduCopter-like vehicle reachable over MAVLink.

    ``sysid`` (default: MAV_SYSID, itself instance + 1 unless saved) is the system id; a fleet
    (:mod:`autopilot_model.fleet`) numbers its vehicles 1..N whatever their instance numbers."""

    def __init__(self, instance: int = 0, urls: Sequence[str] | None = None, speedup: float = 0.0,
                 home: Sequence[float] | None = None, airframe: str | Path | None = None,
                 modules: str | Path | None = None, state_dir: str | Path | None = None,
                 signing_key: bytes | None = None, sensors: str | None = None, use_truth: bool = False,
                 seed: int | None = 0, persist: bool = True, sysid: int | None = None,
                 spin_s: float = 0.0) -> None:
        # imported here, not at the top, for start-up cost only: the command line builds its parser from
        # this module, and the model (numba, shapely) takes about 2 s to import
        from autopilot_model.mavlink.endpoint import MavlinkEndpoint
        from autopilot_model.mavlink.wiring import vehicle_link
        from autopilot_model.modules.flight_modes import FlightModes
        from autopilot_model.modules.gcs_params import define_gcs_params
        from autopilot_model.modules.mission import MissionRunner, MissionStore
        from autopilot_model.modules.pilot_modes import PilotModes
        from autopilot_model.modules.rc_input import RcInput
        from autopilot_model.modules.safety import Safety
        from autopilot_model.vehicle import DEFAULT_HOME, DEFAULT_MODULES, Vehicle

        self.instance = instance
        base = Path(state_dir) if state_dir is not None else default_state_dir()
        self.state_dir = base / f"instance{instance}"
        self.state_dir.mkdir(parents=True, exist_ok=True)
        mod_file = Path(modules) if modules else DEFAULT_MODULES
        kwargs: dict[str, Any] = {"home": tuple(home) if home else DEFAULT_HOME, "speedup": speedup,
                                  "instance": instance, "use_truth": use_truth, "seed": seed,
                                  "spin_s": spin_s}
        if sensors:
            kwargs["sensors"] = sensors
        if persist:
            kwargs["params_file"] = self.state_dir / "params.json"
        self.vehicle = v = Vehicle.from_files(airframe, mod_file, **kwargs)
        # the modules (seed 002 Fig. 2): flight modes, pilot input, missions, failsafes
        self.modes = FlightModes(v)
        v.register("flight_modes.update", self.modes.update)
        self.endpoint = MavlinkEndpoint(v.clock, v.params, list(urls) if urls else default_urls(instance),
                                        sysid=sysid, signing_key=signing_key, instance=instance)
        if sysid is not None:  # a fleet's numbering: wins over a saved MAV_SYSID, as MAV_SYSID's default
            v.params.set_default("MAV_SYSID", sysid)
        self.rc = RcInput(v)
        self.modes.pilot = PilotModes(self.modes, self.rc)
        self.modes.pilot.announce = self.endpoint.statustext
        self.missions = MissionStore(self.state_dir / "missions.json")
        self.mission_runner = MissionRunner(v, self.missions, self.endpoint, self.modes)
        self.modes.mission_runner = self.mission_runner
        self.modes.missions = self.missions  # rally points for RTL
        self.safety = Safety(v, self.endpoint, self.modes, self.missions)
        self.modes.fence = self.safety.fence
        v.register("safety.periodic", self.safety.periodic)
        # the MAVLink side, wired in one place
        self.link = vehicle_link(self.endpoint, v, self.modes, self.rc, self.missions, self.mission_runner,
                                 self.safety)
        define_gcs_params(v.params)  # last: a module's own definition of a name comes first
        for name in v.params.unknown_saved():
            log.warning("%s: unknown parameter %s ignored", self.state_dir / "params.json", name)
        v.select("flight_modes", "mavlink", "mission", "safety")
        v.start()

    # --- running -------------------------------------------------------------------------------
    def run(self, duration_s: float | None = None, stop: threading.Event | None = None) -> None:
        """Run the main loop (paced by the clock's speedup; 0 = as fast as possible)."""
        self.vehicle.run_realtime(duration_s, stop)

    def step(self) -> None:
        """One main-loop iteration (paced only if the vehicle's clock has a speedup; the fleet's do not:
        :class:`autopilot_model.fleet.Fleet` steps its vehicles and paces once for all of them)."""
        self.vehicle.start().step()

    def close(self) -> None:
        self.endpoint.close()


# --- command line ------------------------------------------------------------------------------------
def parse_home(text: str) -> tuple[float, ...]:
    parts = [float(x) for x in text.split(",")]
    if len(parts) not in (3, 4):
        raise argparse.ArgumentTypeError("--home wants LAT,LON,ALT[,HEADING]")
    return tuple(parts)


def add_autopilot_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``taskflight autopilot`` (the vehicle's and the MAVLink side's)."""
    add_model_arguments(parser)
    parser.add_argument("--instance", "-I", type=int, default=0,
                        help="instance N: system id N+1, default ports 5760+10N (TCP) and 14550+10N (UDP)")
    parser.add_argument("--home", type=parse_home, default=None, help="LAT,LON,ALT[,HEADING] (default: CMAC)")
    parser.add_argument("--mavlink", action="append", default=None, metavar="URL",
                        help="udpin:HOST:PORT, udpout:HOST:PORT or tcpin:HOST:PORT (repeatable; "
                             "default tcpin:0.0.0.0:5760+10N and udpin:0.0.0.0:14550+10N)")
    parser.add_argument("--state-dir", default=None,
                        help="where parameters and missions persist "
                             "(default $TASKFLIGHT_STATE or ~/.taskflight)")
    parser.add_argument("--signing-key", default=None, metavar="KEY",
                        help="MAVLink 2 signing: 64 hex digits, or a passphrase (sha256, as MAVProxy)")
    parser.add_argument("--no-persist", action="store_true", help="do not load or save parameters")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many simulated seconds")
    parser.add_argument("--stats", action="store_true",
                        help="time the main loop's task groups and print the scheduler and MAVLink "
                             "statistics at exit (without it the loop runs untimed: ~5 us less per 2 ms "
                             "iteration)")
    parser.add_argument("--spin-us", type=float, default=0.0,
                        help="microseconds of each main-loop period spun before its deadline instead of "
                             "slept (default 0: sleep only, ~0.1 ms of wake-up jitter; 1000 holds a 500 Hz "
                             "loop to tens of microseconds at the cost of half a core)")


def run_autopilot(args: argparse.Namespace) -> int:
    """Run one vehicle until interrupted (or ``--duration``); returns the exit status."""
    from autopilot_model.mavlink.signing import parse_key  # start-up cost, as in Sitl

    key = parse_key(args.signing_key) if getattr(args, "signing_key", None) else None
    speedup = args.speedup if getattr(args, "speedup", None) is not None else 1.0
    try:
        sitl = Sitl(instance=args.instance, urls=args.mavlink, speedup=speedup, home=args.home,
                    airframe=args.airframe, modules=args.modules, state_dir=args.state_dir,
                    signing_key=key, sensors=args.sensors, use_truth=args.truth, seed=args.seed,
                    persist=not args.no_persist, spin_s=getattr(args, "spin_us", 0.0) * 1e-6)
    except (ConfigError, ValueError, OSError) as exc:
        log.error("%s", exc)
        return 2
    sitl.vehicle.start().set_timed(bool(args.stats))  # nobody reads the timing unless asked
    stop = stop_on_signals()
    urls = ", ".join(str(t.url) for t in sitl.endpoint.transports)
    log.info("autopilot instance %d (sysid %d) on %s, speedup %s", args.instance, sitl.endpoint.sysid,
             urls, speedup or "max")
    freeze_startup_heap(f"autopilot instance {args.instance}")
    print(f"READY sysid={sitl.endpoint.sysid} {urls}", flush=True)
    t0 = time.perf_counter()
    try:
        sitl.run(args.duration, stop)
    finally:
        sitl.close()
    if args.stats:
        wall = time.perf_counter() - t0
        sim = sitl.vehicle.clock.now()
        print(f"simulated {sim:.1f} s in {wall:.1f} s wall ({sim / max(wall, 1e-9):.1f}x)")
        for k, val in sorted(sitl.endpoint.stats.items()):
            print(f"  {k:28s} {val}")
        loop = sitl.vehicle.loop
        if loop is not None:
            print(loop.stats.table())
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m autopilot_model.sitl`` = ``taskflight autopilot`` (used by the tests)."""
    parser = argparse.ArgumentParser(prog="autopilot_model.sitl", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="count", default=0)
    add_autopilot_arguments(parser)
    args = parser.parse_args(join_signed_values(argv))
    setup_logging(args.verbose)
    return run_autopilot(args)


if __name__ == "__main__":
    sys.exit(main())
