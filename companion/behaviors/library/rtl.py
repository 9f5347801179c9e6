"""RTL (return to launch): fly home inside the envelope and land there, flown by the companion in GUIDED.

Why the companion flies it rather than switching the autopilot to its own RTL mode (ArduCopter custom mode
6; docs/behaviors.md): the return stays inside the companion's operational envelope (the autopilot's RTL
flies a straight line at RTL_ALT, whatever the envelope), it is supervised like every flight behavior (its
progress, its termination cause, pre-emption by requester priority), and it needs no mode change the queue
would read as a ground station taking the vehicle. If the companion dies, the autopilot's own failsafes
(GUID_TIMEOUT, FS_GCS_ENABLE, the battery failsafe) still bring it home: that path does not depend on us.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from companion.flight import (
    EndCondition,
    FlightCommand,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    VerticalChannel,
    VerticalMode,
)
from companion.flight.setpoint import VehicleState

from ..controller import FlightBehavior, Termination, TerminationCause, register
from ..services import TrajectoryPlanner
from ._common import go_to, need_flying, reference_neu

#: how far (m, horizontally) from home a landing still counts as "at home" (catalog: performance.home_m)
DEFAULT_HOME_TOLERANCE_M = 2.0
#: below the envelope's ceiling by this much (m): a return altitude at the ceiling itself leaves no margin
CEILING_MARGIN_M = 0.5


@register
class ReturnToLaunch(FlightBehavior):
    """Situation: flying (or taking off). Seed 000 Fig. 12b-13b composed: climb where it is to the return
    altitude (``altitude``, the lowest altitude to return at, m above home; without it the current
    altitude), fly the straight line home (local (0, 0): the origin the autopilot's LOCAL_POSITION_NED
    counts from, its home) at that altitude, then descend with allow landing (the link hands the touch-down
    to the autopilot's LAND, which disarms). The return altitude is held inside the envelope's altitude
    band; the altitude actually flown is in the behavior's status (``return_altitude``).

    Goal achieved only when the vehicle is *measured* on the ground (disarmed or landed state) within
    ``performance.home_m`` (default 2 m) of home; landed elsewhere ends it with ``wrong_progress``."""

    behavior = "RTL"
    #: the altitude the return flies at (m above home), once planned
    return_altitude: float | None

    def situation(self, params: Mapping[str, Any]) -> str | None:
        return need_flying(self, or_taking_off=True)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        here = reference_neu(self)
        wanted = max(here[2], float(params["altitude"])) if "altitude" in params else here[2]
        envelope = self.ctx.queue.envelope
        ceiling = envelope.altitude_ceiling
        if ceiling is not None:
            wanted = min(wanted, ceiling - CEILING_MARGIN_M)
        altitude, _ = envelope.clamp_altitude(wanted)
        self.return_altitude = altitude
        planner = self.ctx.processes.get("trajectory_planner")
        assert isinstance(planner, TrajectoryPlanner)
        out: list[FlightCommand] = []
        start = (here[0], here[1], altitude)
        if abs(altitude - here[2]) > 0.2:  # climb (or descend into the band) where it is first
            out.append(go_to(start, straight_line=False))
        out += [go_to(p, params.get("speed")) for p in planner.plan(start, [(0.0, 0.0, altitude)])]
        out.append(FlightCommand(HorizontalChannel(HorizontalMode.DNU),
                                 VerticalChannel(VerticalMode.POS, altitude=0.0, allow_landing=True),
                                 HeadingChannel(HeadingMode.DNU), EndCondition(e_v=True)))
        return out

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.return_altitude = None

    def on_start(self, params: Mapping[str, Any]) -> None:
        self.return_altitude = None
        super().on_start(params)

    def _from_home(self) -> float | None:
        v = self.ctx.vehicle()
        return None if v is None else math.hypot(v.p[0], v.p[1])

    def _tolerance(self) -> float:
        return float(self.descriptor.performance.get("home_m", DEFAULT_HOME_TOLERANCE_M))

    def goal_reached(self) -> bool:
        d = self._from_home()
        return self.flight_state() == "landed" and d is not None and d <= self._tolerance()

    def performance(self, now_s: float) -> Termination | None:
        ended = super().performance(now_s)
        if ended is not None:
            return ended
        d = self._from_home()
        if (self.command_ids and len(self.finished) == len(self.command_ids)
                and self.flight_state() == "landed" and d is not None and d > self._tolerance()):
            return Termination(TerminationCause.WRONG_PROGRESS,
                               f"landed {d:.1f} m from home (more than {self._tolerance():g} m)")
        return None

    def goal_distance(self, vehicle: VehicleState) -> float | None:
        """Away from home: the way left (to the return altitude, then home); over home: the height."""
        horizontal, up = math.hypot(vehicle.p[0], vehicle.p[1]), max(0.0, -vehicle.p[2])
        alt = self.return_altitude
        if horizontal <= self._tolerance() or alt is None:
            return up
        return horizontal + abs(up - alt)

    def status(self) -> dict[str, Any]:
        alt = self.return_altitude
        return {**super().status(), "return_altitude": None if alt is None else round(alt, 2)}
