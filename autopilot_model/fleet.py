"""Many simulated vehicles in one process on one clock (``taskflight up``'s models).

A real-time :class:`~autopilot_model.sitl.Sitl` paces its 500 Hz main loop on the wall by sleeping and then
spinning through the last millisecond of every 2 ms period (:meth:`taskflight_common.clock.SimClock.pace`):
tens
of microseconds of jitter, but half a core per idle vehicle, so ten vehicles in ten processes saturate a
2-core machine. :class:`Fleet` runs N unchanged :class:`Sitl` vehicles (the same classes, every vehicle's
MAVLink exactly as a single one's) in one thread of one process: each main-loop period runs every
vehicle's iteration (seed 002 Sec. 4.2, Fig. 4: events, task groups, world, clock advance), then the
fleet sleeps ONCE for all of them until the next period's deadline on its own :class:`SimClock`, with no
spinning (``spin_s=0``): a period starts late by the OS's wake-up jitter (~0.1 ms, measured by
``bench/bench_fleet.py``), which telemetry at <= 50 Hz hardly sees, and a vehicle costs its iteration's
work only (13-28 us of CPU per 2 ms period with a ground station streaming at 10 Hz, against ~1 ms spun).
``batch`` > 1 runs that many periods back to back before one sleep; ``spin_s`` > 0 spins through the last
``spin_s`` of each wait (less lateness, that much more CPU).

When behind (a loaded machine), periods run back to back until the fleet has caught up; more than
``max_lag_s`` behind, the fleet gives up the lost time (its clock's pacing moves, counted in
``slips``: :meth:`taskflight_common.clock.SimClock.pace`) instead of racing through it. ``speedup=0`` is
lockstep: never waits. The vehicles' main loops run untimed (:meth:`~autopilot_model.scheduler.mainloop.
MainLoop.set_timed`: their shared period's lateness is the fleet's measure, and the stamps were about a
quarter of a vehicle's iteration); the collector's full passes over the vehicles' long-lived objects, which a
single vehicle's sleep hides, are avoided (``gc.freeze`` once they are built).

Vehicle ``i`` (from 0) is instance ``base_instance + i``: system id ``first_sysid + i`` (MAV_SYSID; 1..N
by default, whatever the instance numbers: a ground station sees a fleet as 1..N), the endpoints of
a single Sitl of that instance (TCP 5760+10N for MAVProxy/QGroundControl, UDP 14550+10N listening), its
parameters and missions in ``<state-dir>/instance<N>/``, and its home ``spacing_m`` metres east of
the previous vehicle's, in rows of ten, each row ``spacing_m`` south of the previous (so vehicles do not
sit on each other, and 50 stay within 45 m by 20 m: :func:`fleet_homes`).

    python -m autopilot_model.fleet --vehicles 12 [--speedup 1] [--base-instance 0] [--spacing 5]
"""

from __future__ import annotations

import argparse
import gc
import logging
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

from autopilot_model.demo import add_model_arguments
from autopilot_model.sitl import Sitl, default_urls, parse_home
from taskflight_common.cliargs import join_signed_values
from taskflight_common.clock import SimClock
from taskflight_common.geo import home_offset, ned_to_geodetic
from taskflight_common.ports import model_ports
from taskflight_common.runtime import die_with_parent, setup_logging, stop_on_signals
from taskflight_common.yamlio import ConfigError

log = logging.getLogger(__name__)

#: periods of lateness kept for the statistics (two minutes at 500 Hz)
LATENESS_KEPT = 60_000


def fleet_homes(n: int, home: Sequence[float] | None = None, spacing_m: float = 5.0
                ) -> list[tuple[float, ...]]:
    """Homes of ``n`` vehicles: ``home`` (LAT, LON, ALT[, HDG]; default CMAC) and then every ``spacing_m``
    metres east of it, in rows of ten, each row ``spacing_m`` south of the previous
    (:func:`taskflight_common.geo.home_offset`; ArduPilot's flat-earth conversion)."""
    from autopilot_model.vehicle import DEFAULT_HOME  # start-up cost: the model imports numba

    base = tuple(float(x) for x in (home if home is not None else DEFAULT_HOME))
    if len(base) not in (3, 4):
        raise ValueError(f"a home is LAT,LON,ALT[,HEADING], got {base}")
    if not spacing_m >= 0:
        raise ValueError(f"spacing must be >= 0 m, got {spacing_m}")
    out = []
    for i in range(n):
        north, east = home_offset(i, spacing_m)
        lat, lon, alt = ned_to_geodetic((base[0], base[1], base[2]), north, east, 0.0)
        out.append((lat, lon, alt, *base[3:]))
    return out


def template_urls(templates: Sequence[str], instance: int, sysid: int | None = None) -> list[str]:
    """Endpoint URLs of ``instance`` from templates with ``{instance}``, ``{sysid}`` (default instance+1),
    ``{tcp}`` (5760+10N) and ``{udp}`` (14550+10N), e.g. ``udpin:127.0.0.1:{udp}``."""
    tcp, udp = model_ports(instance)
    fields = {"instance": instance, "sysid": instance + 1 if sysid is None else sysid, "tcp": tcp, "udp": udp}
    out = []
    for t in templates:
        try:
            out.append(t.format(**fields))
        except (KeyError, IndexError, ValueError) as exc:
            raise ValueError(f"bad MAVLink URL template {t!r}: {exc!r} (fields: instance, sysid, tcp, udp)"
                             ) from None
    return out


class Fleet:
    """N :class:`~autopilot_model.sitl.Sitl` vehicles stepped together on one paced clock."""

    def __init__(self, n: int, speedup: float = 1.0, homes: Sequence[Sequence[float]] | None = None,
                 base_instance: int = 0, state_dir: str | Path | None = None, *,
                 home: Sequence[float] | None = None, spacing_m: float = 5.0,
                 urls: Sequence[Sequence[str]] | None = None, url_templates: Sequence[str] | None = None,
                 first_sysid: int = 1, batch: int = 1, max_lag_s: float = 0.5, spin_s: float = 0.0,
                 **sitl_options: Any) -> None:
        if n < 1:
            raise ValueError(f"a fleet has at least one vehicle, got {n}")
        if not 0 <= base_instance <= 255 - n:
            raise ValueError(f"instances {base_instance}..{base_instance + n - 1} are not all within 0..254")
        if not 1 <= first_sysid <= 256 - n:
            raise ValueError(f"system ids {first_sysid}..{first_sysid + n - 1} are not all within 1..255")
        if batch < 1:
            raise ValueError(f"batch must be >= 1 period, got {batch}")
        if homes is None:
            homes = fleet_homes(n, home, spacing_m)
        elif len(homes) != n:
            raise ValueError(f"{len(homes)} homes for {n} vehicles")
        if urls is not None and len(urls) != n:
            raise ValueError(f"{len(urls)} URL lists for {n} vehicles")
        self.clock = SimClock(speedup, spin_s=spin_s, max_lag_s=max_lag_s)
        self.batch = batch
        self.vehicles: list[Sitl] = []
        seed = sitl_options.pop("seed", 0)
        try:
            for i in range(n):
                inst = base_instance + i
                if urls is not None:
                    mine = list(urls[i])
                elif url_templates:
                    mine = template_urls(url_templates, inst, first_sysid + i)
                else:
                    mine = default_urls(inst)
                # speedup 0: the vehicle's own loop never paces; the fleet's clock does, once for all
                self.vehicles.append(Sitl(instance=inst, urls=mine, speedup=0.0, home=homes[i],
                                          sysid=first_sysid + i, state_dir=state_dir,
                                          seed=None if seed is None else seed + i,
                                          **sitl_options))
        except BaseException:
            self.close()
            raise
        periods = {s.vehicle.start().period_us for s in self.vehicles}
        if len(periods) != 1:
            self.close()
            raise ValueError(f"the vehicles' main loop periods differ ({sorted(periods)} us): one clock "
                             "needs one period")
        self.period_us = periods.pop()
        for s in self.vehicles:  # one shared period: the fleet measures its lateness (lateness_s)
            s.vehicle.start().set_timed(False)
        self.rounds = 0
        """Main-loop periods run (every vehicle one iteration each)."""
        self.lateness_s: deque[float] = deque(maxlen=LATENESS_KEPT)
        """Wall seconds by which each recent period started after its deadline (real time only)."""
        # the vehicles' ~3000 objects each live as long as the fleet: out of the collector's sight, a full
        # collection takes microseconds instead of ~40-80 ms (50 vehicles), which would be a late period
        gc.freeze()

    # --- reading -------------------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.vehicles)

    @property
    def speedup(self) -> float:
        return self.clock.speedup

    def describe(self) -> str:
        """``sysid=K URL,URL`` of every vehicle, ``;``-separated (the READY line)."""
        return "; ".join(f"sysid={s.endpoint.sysid} " + ",".join(str(t.url) for t in s.endpoint.transports)
                         for s in self.vehicles)

    def lateness_quantiles(self, qs: Sequence[float]) -> list[float]:
        """Quantiles (nearest rank) of the recent periods' lateness in seconds (NaN before any)."""
        data = sorted(self.lateness_s)
        if not data:
            return [float("nan")] * len(qs)
        return [data[min(len(data) - 1, int(q * (len(data) - 1) + 0.5))] for q in qs]

    def reset_stats(self) -> None:
        """Forget the lateness and slips measured so far (a bench's measured interval starts)."""
        self.lateness_s.clear()
        self.clock.slips = 0
        self.clock.given_up_s = 0.0

    @property
    def max_lag_s(self) -> float:
        """Wall seconds the fleet may fall behind before it gives the lost time up."""
        return self.clock.max_lag_s

    @property
    def slips(self) -> int:
        """Times the fleet was more than ``max_lag_s`` behind and gave the lost time up."""
        return self.clock.slips

    # --- running -------------------------------------------------------------------------------------
    def start_pacing(self) -> None:
        """Anchor the pacing here: the next period is due now (after construction, warm-up, a pause)."""
        self.clock.set_speedup(self.clock.speedup)

    def run(self, duration_s: float | None = None, stop: threading.Event | None = None) -> int:
        """Run ``duration_s`` simulated seconds (None: until ``stop`` is set); returns the periods run.

        ``stop`` is checked every 8 periods. Pacing is anchored at the call, after the very first period
        (each vehicle's first iteration loads compiled kernels: tenths of a second, not a late period)."""
        if duration_s is not None and not duration_s >= 0:
            raise ValueError(f"duration must be >= 0 s (None: until stopped), got {duration_s}")
        steps: tuple[Callable[[], None], ...] = tuple(s.vehicle.start().step for s in self.vehicles)
        clock = self.clock
        period = self.period_us
        todo = -1 if duration_s is None else round(duration_s * 1e6 / period)
        warm = 0
        if self.rounds == 0 and todo != 0:
            for step in steps:
                step()
            clock.advance(period)
            self.rounds = warm = 1
            todo = max(todo - 1, 0) if todo > 0 else todo
            # one wall time at simulated t = 0 for all (SYSTEM_TIME): the moment the fleet starts, not
            # each vehicle's construction, seconds apart for 50 vehicles
            unix0_us = int(time.time() * 1e6) - clock.now_us
            for sitl in self.vehicles:
                sitl.link.telemetry.unix0_us = unix0_us
        paced = clock.speedup > 0
        batch = self.batch
        late = self.lateness_s.append
        lag_of = clock.wall_lag
        self.start_pacing()
        done = 0
        while done != todo:
            if (done & 7) == 0 and stop is not None and stop.is_set():
                break
            if paced and done % batch == 0:
                late(lag_of())
            for step in steps:
                step()
            clock.advance(period)
            done += 1
            if paced and done % batch == 0:
                clock.pace()
        self.rounds += done
        return warm + done

    def close(self) -> None:
        """Close every vehicle's endpoint (its ports are free on return)."""
        for s in self.vehicles:
            try:
                s.close()
            except Exception:  # one vehicle's close must not leave the others' ports open
                log.exception("closing vehicle instance %d", s.instance)

    def __enter__(self) -> Fleet:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


# --- command line ------------------------------------------------------------------------------------
def add_fleet_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``python -m autopilot_model.fleet`` / ``taskflight fleet``."""
    add_model_arguments(parser)
    parser.add_argument("--vehicles", "-n", type=int, required=True, help="number of vehicles N")
    parser.add_argument("--base-instance", "-I", type=int, default=0,
                        help="instance of vehicle 0 (vehicle i: instance I+i, ports "
                             "5760+10(I+i) TCP and 14550+10(I+i) UDP)")
    parser.add_argument("--first-sysid", type=int, default=1,
                        help="system id of vehicle 0 (vehicle i: this + i; default 1)")
    parser.add_argument("--home", type=parse_home, default=None,
                        help="LAT,LON,ALT[,HEADING] of vehicle 0 (default: CMAC)")
    parser.add_argument("--spacing", type=float, default=5.0,
                        help="metres between two homes, east in rows of ten, rows south (default 5)")
    parser.add_argument("--mavlink-template", action="append", default=None, metavar="URL",
                        help="endpoint URL with {instance}, {sysid}, {tcp}, {udp} (repeatable; default "
                             "tcpin:0.0.0.0:{tcp} and udpin:0.0.0.0:{udp})")
    parser.add_argument("--state-dir", default=None,
                        help="where parameters and missions persist, one instanceN folder per vehicle "
                             "(default $TASKFLIGHT_STATE or ~/.taskflight)")
    parser.add_argument("--no-persist", action="store_true", help="do not load or save parameters")
    parser.add_argument("--batch", type=int, default=1, help="periods run back to back per sleep (default 1)")
    parser.add_argument("--spin-us", type=float, default=0.0,
                        help="microseconds spun before each deadline instead of slept (default 0)")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many simulated seconds")
    parser.add_argument("--stats", action="store_true", help="print the fleet's pacing statistics at exit")


def run_fleet(args: argparse.Namespace) -> int:
    """Run the fleet until interrupted (or ``--duration``); returns the exit status."""
    speedup = args.speedup if args.speedup is not None else 1.0
    try:
        fleet = Fleet(args.vehicles, speedup, base_instance=args.base_instance, state_dir=args.state_dir,
                      first_sysid=args.first_sysid, home=args.home, spacing_m=args.spacing,
                      url_templates=args.mavlink_template,
                      batch=args.batch, spin_s=args.spin_us * 1e-6, airframe=args.airframe,
                      modules=args.modules, sensors=args.sensors,
                      use_truth=args.truth, seed=args.seed, persist=not args.no_persist)
    except (ConfigError, ValueError, OSError) as exc:
        log.error("%s", exc)
        return 2
    stop = stop_on_signals()
    log.info("fleet of %d vehicles, speedup %s", len(fleet), speedup or "max")
    print(f"READY vehicles={len(fleet)} {fleet.describe()}", flush=True)
    t0 = time.perf_counter()
    try:
        fleet.run(args.duration, stop)
    finally:
        fleet.close()
    if args.stats:
        print(format_stats(fleet, time.perf_counter() - t0))
    return 0


def format_stats(fleet: Fleet, wall_s: float) -> str:
    """Simulated speed, periods, slips and the lateness quantiles (one line)."""
    sim = fleet.rounds * fleet.period_us * 1e-6
    p50, p99 = fleet.lateness_quantiles((0.5, 0.99))
    return (f"fleet: {len(fleet)} vehicles, {sim:.1f} s simulated in {wall_s:.1f} s wall "
            f"({sim / max(wall_s, 1e-9):.2f}x), {fleet.rounds} periods, {fleet.slips} slips, "
            f"period lateness p50 {p50 * 1e6:.0f} us p99 {p99 * 1e6:.0f} us")


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m autopilot_model.fleet`` = ``taskflight fleet``."""
    parser = argparse.ArgumentParser(prog="autopilot_model.fleet", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="count", default=0)
    add_fleet_arguments(parser)
    args = parser.parse_args(join_signed_values(argv))
    die_with_parent()  # a child of taskflight up stops when it dies
    setup_logging(args.verbose)
    return run_fleet(args)


if __name__ == "__main__":
    sys.exit(main())
