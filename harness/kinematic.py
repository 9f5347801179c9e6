"""Stand-ins shared by the mission and failsafe logic tests (no tests here): a kinematic vehicle whose
navigator flies straight to its target at a fixed speed (the library's
:class:`~companion.flight.simulate.PointMass`), on a clock the test advances, and an endpoint
that records what would be sent."""

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
    def __init__(self) -> None:
        self.mav = mavlink.MAVLink(None, 1, 1)
        self.sent: list[Any] = []
        self.texts: list[str] = []

    def send(self, msg: Any, link: Any = None) -> None:
        self.sent.append(msg)

    def statustext(self, severity: int, text: str) -> None:
        self.texts.append(text)


def geo(n: float, e: float) -> tuple[int, int]:
    lat, lon, _ = ned_to_geodetic(HOME, n, e, 0.0)
    return round(lat * 1e7), round(lon * 1e7)
