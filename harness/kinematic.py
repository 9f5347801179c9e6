"""Stand-ins shared by the mission, failsafe and fence logic tests (no tests here): a kinematic vehicle whose
navigator flies straight to its target at a fixed speed (the library's
:class:`~companion.flight.simulate.PointMass`), on a clock the test advances, an endpoint that records
what would be sent (and when a ground station was last heard), and a mode switch that records what it
was asked."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from autopilot_model.params import ParamStore
from autopilot_model.physics.battery import Battery
from companion.flight.simulate import PointMass
from taskflight_common.geo import ned_to_geodetic

HOME = (-35.363261, 149.165230, 584.0)
ON_GROUND, IN_AIR, TAKEOFF, LANDING = 1, 2, 3, 4


class KinematicNav:
    """Navigator stand-in: moves the position straight to the target at a fixed speed."""

    def __init__(self, v: KinematicVehicle) -> None:
        self.v = v
        self.armed = False
        self.landed_state = ON_GROUND
        self.target: tuple[float, float, float] | None = None
        self.speed = 5.0
        self.landing = False
        self.speeds: list[float | None] = []
        self.prearm_checks: list[Callable[[], str | None]] = []  # as the Navigator's

    def arm(self, force: bool = False) -> tuple[bool, str]:
        self.armed = True
        return True, ""

    def disarm(self, force: bool = False) -> tuple[bool, str]:
        self.armed = False
        return True, ""

    def takeoff(self, alt_m: float) -> tuple[bool, str]:
        p = self.v.state.position_ned
        self.target = (p[0], p[1], -alt_m)
        self.landed_state = TAKEOFF
        return True, ""

    def goto(self, p: tuple[float, float, float], speed: float | None = None) -> tuple[bool, str]:
        assert self.landed_state != ON_GROUND
        self.target = tuple(p)
        self.speeds.append(speed)
        return True, ""

    def hold(self) -> tuple[bool, str]:
        self.target = self.v.state.position_ned
        return True, ""

    def land(self) -> tuple[bool, str]:
        p = self.v.state.position_ned
        self.target = (p[0], p[1], 0.0)
        self.landing = True
        self.landed_state = LANDING
        return True, ""

    def step(self, dt: float) -> None:
        if self.target is None or not self.armed:
            return
        body = PointMass(self.v.state.position_ned, speed=self.speed)  # the library's stand-in
        arrived = body.straight_toward(self.target, dt)
        self.v.state.position_ned = body.p
        if self.landed_state == TAKEOFF and arrived:
            self.landed_state = IN_AIR
        if self.landing and arrived:
            self.landing, self.landed_state, self.armed = False, ON_GROUND, False


class KinematicVehicle:
    def __init__(self) -> None:
        self.params = ParamStore()
        self.home = HOME
        self.state = type("S", (), {})()
        self.state.origin = HOME
        self.state.position_ned = (0.0, 0.0, 0.0)
        self.clock = type("C", (), {})()
        self.t = 0.0
        self.clock.now = lambda: self.t
        self.nav = KinematicNav(self)
        self.battery = Battery()
        self.battery_voltage = self.battery.voltage
        self.guidance = type("G", (), {"at_target": False})()

    def run(self, seconds: float, *callbacks: Any, dt: float = 0.02) -> None:
        for _ in range(round(seconds / dt)):
            self.t += dt
            self.nav.step(dt)
            self.guidance.at_target = self.nav.target is not None and \
                math.dist(self.state.position_ned, self.nav.target) < 1e-6
            for cb in callbacks:
                cb()


class Recorder:
    """The MAVLink endpoint stand-in: what would be sent, the status texts, the last GCS heartbeat."""

    #: when a ground station's heartbeat was last heard (vehicle seconds); None: never (the GCS failsafe)
    last_gcs_heartbeat_s: float | None = None

    def __init__(self) -> None:
        self.mav = mavlink.MAVLink(None, 1, 1)
        self.sent: list[Any] = []
        self.texts: list[str] = []

    def send(self, msg: Any, link: Any = None) -> None:
        self.sent.append(msg)

    def statustext(self, severity: int, text: str) -> None:
        self.texts.append(text)


class ModeSwitch:
    """The flight-mode switch stand-in: records each mode asked for (``calls``) with its reason
    (``reasons``); a mode in ``deny`` is refused (as a mode whose checks fail)."""

    def __init__(self, mode: int = 4) -> None:  # GUIDED
        self.mode = mode
        self.calls: list[int] = []
        self.reasons: list[str] = []
        self.deny: set[int] = set()

    def set_mode(self, mode: int, reason: str = "") -> tuple[bool, str]:
        self.calls.append(mode)
        self.reasons.append(reason)
        if mode in self.deny:
            return False, "denied"
        self.mode = mode
        return True, ""


def fly(v: KinematicVehicle, ned: tuple[float, float, float]) -> None:
    """The vehicle armed and in the air at ``ned`` (the failsafe and fence tests' starting point)."""
    v.nav.armed = True
    v.nav.landed_state = IN_AIR
    v.state.position_ned = ned


def geo(n: float, e: float) -> tuple[int, int]:
    lat, lon, _ = ned_to_geodetic(HOME, n, e, 0.0)
    return round(lat * 1e7), round(lon * 1e7)
