"""Scripted flights on the model's Python API, shared by the demo, the tests and the bench.

:func:`fly_square` flies seed 000's kind of test pattern: take off, a square at a given speed, land,
recording the true position against the setpoint generator's P_d, so tracking error is measured on the
same flight everywhere.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field

from autopilot_model.modules.navigation import LANDED_IN_AIR, LANDED_ON_GROUND
from autopilot_model.vehicle import Vehicle

log = logging.getLogger(__name__)


class FlightError(RuntimeError):
    """A scripted flight did not reach a stage in time."""


@dataclass
class TrackingRecord:
    """Samples of truth minus P_d during the part of a flight that is scored."""

    horizontal: list[float] = field(default_factory=list)
    vertical: list[float] = field(default_factory=list)

    def add(self, vehicle: Vehicle) -> None:
        x = vehicle.world.x
        p = vehicle.guidance.p
        self.horizontal.append(math.hypot(x[0] - p[0], x[1] - p[1]))
        self.vertical.append(abs(x[2] - p[2]))

    @staticmethod
    def _rms(v: list[float]) -> float:
        return math.sqrt(sum(e * e for e in v) / len(v)) if v else math.nan

    def summary(self) -> dict[str, float]:
        return {
            "h_rms": self._rms(self.horizontal), "h_max": max(self.horizontal, default=math.nan),
            "v_rms": self._rms(self.vertical), "v_max": max(self.vertical, default=math.nan),
            "samples": float(len(self.horizontal)),
        }


def _require(ok_reason: tuple[bool, str], what: str) -> None:
    ok, reason = ok_reason
    if not ok:
        raise FlightError(f"{what}: {reason}")


def _run_until(v: Vehicle, pred: Callable[[], bool], timeout_s: float, what: str,
               record: TrackingRecord | None = None) -> None:
    end = v.clock.now() + timeout_s
    while v.clock.now() < end:
        v.step(10)
        if record is not None:
            record.add(v)
        if pred():
            return
    raise FlightError(f"{what} not reached within {timeout_s:g} s of simulated time")


def takeoff(v: Vehicle, alt: float = 10.0, timeout_s: float = 30.0) -> None:
    if not v.wait_estimator(10.0):
        raise FlightError("estimator did not become healthy")
    _require(v.nav.arm(), "arm")
    _require(v.nav.takeoff(alt), "takeoff")
    _run_until(v, lambda: v.nav.landed_state == LANDED_IN_AIR, timeout_s, "take-off altitude")


def land(v: Vehicle, timeout_s: float = 60.0) -> None:
    _require(v.nav.land(), "land")
    _run_until(v, lambda: v.nav.landed_state == LANDED_ON_GROUND and not v.nav.armed, timeout_s, "landing")


def goto(v: Vehicle, p: tuple[float, float, float], speed: float, timeout_s: float = 60.0,
         record: TrackingRecord | None = None) -> None:
    _require(v.nav.goto(p, speed), "goto")
    _run_until(v, lambda: v.guidance.at_target, timeout_s, f"waypoint {p}", record)


def fly_square(v: Vehicle, side: float = 50.0, speed: float = 5.0, alt: float = 10.0,
               progress: Callable[[str], None] | None = None) -> TrackingRecord:
    """Take off to ``alt``, fly a square of ``side`` metres at ``speed`` and land; returns the tracking
    record of the square (truth against P_d)."""
    say = progress or log.info
    say(f"take-off to {alt:g} m")
    takeoff(v, alt)
    v.run_for(2.0)  # settle
    rec = TrackingRecord()
    n0, e0, _ = v.guidance.p
    corners = [(n0 + side, e0), (n0 + side, e0 + side), (n0, e0 + side), (n0, e0)]
    for i, (n, e) in enumerate(corners):
        say(f"leg {i + 1}/4 to N {n:.0f} E {e:.0f} at {speed:g} m/s")
        goto(v, (n, e, -alt), speed, timeout_s=side / speed * 3 + 20, record=rec)
    v.run_for(2.0)
    say("landing")
    land(v)
    return rec
