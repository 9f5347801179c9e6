"""What a vehicle can do, for delegation (seed 000 Sec. III-A): the :class:`Platform`.

Seed 000 Sec. III-A: ``get_constraints()`` returns the constraints "which are platform-specific" (e.g. "a
maximum duration of a task which is limited by the current fuel level") and ``check()`` verifies "whether
the execution can be performed with the provided input parameters as well as checking whether other
platform-specific requirements are met", e.g. "whether a camera or a laser range finder sensors are
present". A :class:`Platform` holds those facts for one vehicle:

* ``home`` (lat, lon): the origin of the local frame (north, east, up) missions are converted to;
* ``envelope`` (:class:`~companion.flight.limits.Envelope`, the operational fence) and ``limits``
  (:class:`~companion.flight.limits.Limits`, the maximum speeds and accelerations);
* the qualitative ``speeds`` (``slow | standard | fast``, m/s) and ``altitudes`` (``low | standard |
  high``, m above home) the task parameters of Fig. 12a / 14a map to;
* ``takeoff_altitude`` (Sec. VI-A: 2 m indoor, 5 m outdoor; ``profile`` picks the default; ``null``: none,
  each take-off node gives its ``altitude`` or is refused), and the
  allowed flight altitudes ``altitude_min`` / ``altitude_max``;
* ``sensors`` (sensor type -> :class:`~companion.sensing.footprint.Sensor`) and ``range_sensor`` (a
  ground range finder: without one, follow-ground flight is refused, Sec. VI-B);
* the battery: ``endurance_s`` = capacity at 100 % x remaining fraction - reserve;
* ``autopilot_params``: autopilot parameters that bound flight (ArduCopter names, see
  :data:`BOUNDING_PARAMS`); each tightens the limits above, the others are kept and ignored;
* ``tasks``: the task types this platform has an executor for ("Each of the platforms participating in
  a mission supports a subset of the tasks", seed 000 abstract).

The YAML form (``mission_specs/platform_indoor.yaml``, ``platform_outdoor.yaml``) is read by
:func:`load_platform` with errors naming file, line and field.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from companion.flight.limits import Envelope, Limits
from companion.sensing.footprint import Sensor
from companion.tst.registry import leaf_type_names
from mission_specs import bundled
from taskflight_common.yamlio import Fields, load_yaml

log = logging.getLogger(__name__)

__all__ = ["BOUNDING_PARAMS", "PROFILES", "Platform", "bundled_platform", "load_platform",
           "platform_from_dict"]

#: ``profile`` -> default take-off altitude (m), seed 000 Sec. VI-A (2 m indoor, 5 m outdoor).
PROFILES: dict[str, float] = {"indoor": 2.0, "outdoor": 5.0}
#: The autopilot parameters that tighten the platform's limits (ArduCopter names and units).
BOUNDING_PARAMS: dict[str, str] = {
    "WPNAV_SPEED": "horizontal speed limit, cm/s",
    "WPNAV_SPEED_UP": "climb speed limit, cm/s",
    "WPNAV_SPEED_DN": "descent speed limit, cm/s",
    "WPNAV_ACCEL": "horizontal acceleration limit, cm/s/s",
    "FENCE_ALT_MAX": "fence ceiling, m",
    "FENCE_RADIUS": "circular fence around home, m",
}
SPEED_NAMES = ("slow", "standard", "fast")
ALTITUDE_NAMES = ("low", "standard", "high")
SENSOR_TYPES = ("camera", "laser", "artva")
_KEYS = ("platform", "description", "profile", "home", "sensor_profile", "speeds", "altitudes",
         "takeoff_altitude", "altitude_min", "altitude_max", "limits", "envelope", "sensors", "battery",
         "autopilot_params", "tasks")


@dataclass(frozen=True)
class Platform:
    """The delegation view of one vehicle (see the module docstring)."""

    name: str
    home: tuple[float, float]
    envelope: Envelope = field(default_factory=Envelope)
    limits: Limits = field(default_factory=Limits)
    speeds: Mapping[str, float] = field(default_factory=lambda: {"slow": 1.0, "standard": 2.0, "fast": 4.0})
    altitudes: Mapping[str, float] = field(
        default_factory=lambda: {"low": 3.0, "standard": 5.0, "high": 10.0})
    profile: str = "outdoor"
    takeoff_altitude: float | None = 5.0
    altitude_min: float = 0.0
    altitude_max: float | None = None
    sensors: Mapping[str, Sensor] = field(default_factory=lambda: {"camera": Sensor()})
    range_sensor: bool = False
    battery_capacity_s: float = 900.0
    battery_percent: float = 100.0
    reserve_s: float = 0.0
    autopilot_params: Mapping[str, float] = field(default_factory=dict)
    tasks: tuple[str, ...] = field(default_factory=leaf_type_names)
    sensor_profile: str | None = None
    description: str = ""

    # --- derived quantities: the tightest of config, limits, envelope and autopilot parameters ------------
    @property
    def endurance_s(self) -> float:
        """Flight time left: capacity x remaining fraction - reserve (never below 0)."""
        return max(0.0, self.battery_capacity_s * self.battery_percent / 100.0 - self.reserve_s)

    @property
    def endurance_source(self) -> str:
        return (f"battery {self.battery_percent:g} % of {self.battery_capacity_s:g} s, "
                f"reserve {self.reserve_s:g} s")

    def _tightest(self, candidates: list[tuple[float | None, str]], lowest: bool = True) -> tuple[float, str]:
        known = [(v, why) for v, why in candidates if v is not None]
        if not known:
            return (math.inf if lowest else -math.inf), "none"
        known.reverse()  # on a tie, the later source (the autopilot's parameter) is named
        return min(known, key=lambda c: c[0]) if lowest else max(known, key=lambda c: c[0])

    @property
    def max_speed(self) -> tuple[float, str]:
        """(max horizontal speed m/s, where it comes from)."""
        p = self.autopilot_params
        return self._tightest([(self.limits.horizontal_speed, "limits.horizontal_speed"),
                               (p["WPNAV_SPEED"] / 100.0 if "WPNAV_SPEED" in p else None, "WPNAV_SPEED")])

    @property
    def max_climb(self) -> float:
        p = self.autopilot_params
        return self._tightest([(self.limits.vertical_speed, ""),
                               (p["WPNAV_SPEED_UP"] / 100.0 if "WPNAV_SPEED_UP" in p else None, "")])[0]

    @property
    def max_descent(self) -> float:
        p = self.autopilot_params
        return self._tightest([(self.limits.vertical_speed, ""),
                               (p["WPNAV_SPEED_DN"] / 100.0 if "WPNAV_SPEED_DN" in p else None, "")])[0]

    @property
    def max_accel(self) -> float:
        p = self.autopilot_params
        return self._tightest([(self.limits.horizontal_acceleration, ""),
                               (p["WPNAV_ACCEL"] / 100.0 if "WPNAV_ACCEL" in p else None, "")])[0]

    @property
    def ceiling(self) -> tuple[float, str]:
        """(highest allowed altitude m above home, where it comes from); inf when unbounded."""
        return self._tightest([(self.altitude_max, "altitude_max"),
                               (self.envelope.altitude_ceiling, "envelope ceiling"),
                               (self.autopilot_params.get("FENCE_ALT_MAX"), "FENCE_ALT_MAX")])

    @property
    def floor(self) -> tuple[float, str]:
        """(lowest allowed flight altitude m above home, where it comes from)."""
        return self._tightest([(self.altitude_min, "altitude_min"),
                               (self.envelope.altitude_floor, "envelope floor")], lowest=False)

    def fence_reason(self, ne: tuple[float, float]) -> str | None:
        """Why the local point (north, east) is outside the fence, or None when inside."""
        if not self.envelope.contains_ne(ne):
            return "outside the operational envelope (fence)"
        radius = self.autopilot_params.get("FENCE_RADIUS")
        if radius is not None and math.hypot(ne[0], ne[1]) > radius:
            return f"outside the fence radius {radius:g} m (FENCE_RADIUS)"
        return None

    def segment_reason(self, a: tuple[float, float], b: tuple[float, float]) -> str | None:
        """Why the straight flight a -> b (local north, east) leaves the fence, or None."""
        for p in (a, b):
            why = self.fence_reason(p)
            if why:
                return why
        if not self.envelope.covers_segment(a, b):
            return "the straight line leaves the operational envelope (fence)"
        return None

    # --- the one envelope: what the queue flies is what delegation checks --------------------------------
    def flight_limits(self) -> Limits:
        """The queue's limits (seed 000 Sec. IV-D v_env, a_env): ``limits`` tightened by the autopilot's
        parameters, the same maxima delegation plans with (``max_speed``, ``max_climb``, ...)."""
        return dataclasses.replace(self.limits, horizontal_speed=self.max_speed[0],
                                   vertical_speed=min(self.max_climb, self.max_descent),
                                   horizontal_acceleration=self.max_accel)

    def flight_envelope(self) -> Envelope:
        """The queue's operational envelope (p_env): the fence (``envelope``'s box or polygon, cut to a
        polygon inscribed in ``FENCE_RADIUS`` when given), the ceiling and floor delegation checks."""
        ceiling, floor = self.ceiling[0], self.floor[0]
        env = Envelope(list(self.envelope.vertices) if self.envelope.vertices else None,
                       altitude_floor=floor if floor > 0 else None,
                       altitude_ceiling=ceiling if math.isfinite(ceiling) else None)
        radius = self.autopilot_params.get("FENCE_RADIUS")
        if radius is not None:
            n = 64  # inscribed: every point of the polygon is inside the circle
            angles = [2 * math.pi * k / n for k in range(n)]
            env = env.intersected([(radius * math.cos(a), radius * math.sin(a)) for a in angles])
        return env

    # --- helpers the companion uses with its MAVLink mirror ----------------------------------------------
    def with_battery(self, percent: float) -> Platform:
        """This platform with ``percent`` of the battery left (0-100)."""
        if not (isinstance(percent, int | float) and 0.0 <= percent <= 100.0):
            raise ValueError(f"battery percent must be in [0, 100], got {percent!r}")
        return dataclasses.replace(self, battery_percent=float(percent))

    def with_home(self, lat: float, lon: float) -> Platform:
        """This platform with another home (the envelope stays relative to home)."""
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            raise ValueError(f"home ({lat}, {lon}) out of range")
        return dataclasses.replace(self, home=(float(lat), float(lon)))

    def with_tasks(self, tasks: tuple[str, ...]) -> Platform:
        """This platform with executors for ``tasks`` only."""
        return dataclasses.replace(self, tasks=tuple(tasks))

    def summary(self) -> dict[str, Any]:
        """The platform's delegation quantities, for JSON."""
        return {"name": self.name, "profile": self.profile, "home": list(self.home),
                "speeds": dict(self.speeds), "altitudes": dict(self.altitudes),
                "takeoff_altitude": self.takeoff_altitude, "max_speed": self.max_speed[0],
                "ceiling": self.ceiling[0], "floor": self.floor[0], "endurance_s": self.endurance_s,
                "sensors": sorted(self.sensors), "range_sensor": self.range_sensor, "tasks": list(self.tasks)}


def load_platform(path: str | Path) -> Platform:
    """Read a platform YAML file; raises :class:`~taskflight_common.yamlio.ConfigError` (file:line: field)."""
    platform = platform_from_dict(load_yaml(path), str(path))
    log.info("platform %s from %s: endurance %.0f s, ceiling %g m", platform.name, path,
             platform.endurance_s, platform.ceiling[0])
    return platform


def bundled_platform(profile: str = "indoor") -> Platform:
    """``mission_specs/platform_{profile}.yaml`` (indoor or outdoor)."""
    if profile not in PROFILES:
        raise ValueError(f"profile must be one of {', '.join(PROFILES)}, got {profile!r}")
    return load_platform(bundled(f"platform_{profile}.yaml"))


def _options(f: Fields, key: str, names: tuple[str, ...], default: Mapping[str, float]) -> dict[str, float]:
    if not f.has(key):
        return dict(default)
    sub = f.sub(key)
    sub.unknown(names)
    out = {n: sub.number(n, positive=True) for n in names}
    values = [out[n] for n in names]
    if values != sorted(values):
        raise sub.error(None, f"expected {' <= '.join(names)}")
    return out


def platform_from_dict(data: Any, file: str | None = None) -> Platform:
    """Validate a platform given as data (parsed YAML keeping lines, or JSON)."""
    f = Fields(data, "", file or "<input>")
    f.unknown(_KEYS)
    name = f.string("platform")
    profile = f.string("profile", "outdoor", choices=PROFILES)
    home = f.vector("home", 2)
    if not (-90 <= home[0] <= 90 and -180 <= home[1] <= 180):
        raise f.error("home", "latitude in [-90, 90] and longitude in [-180, 180] expected")
    defaults = Platform("default", (0.0, 0.0))
    limits = Limits.from_fields(f.sub("limits")) if f.has("limits") else Limits()
    envelope = Envelope.from_fields(f.sub("envelope")) if f.has("envelope") else Envelope()
    alt_min = f.number("altitude_min", 0.0, lo=0.0)
    alt_max = f.number("altitude_max", None) if f.raw("altitude_max", None) is not None else None
    if alt_max is not None and alt_max <= alt_min:
        raise f.error("altitude_max", f"must be above altitude_min {alt_min:g}")
    takeoff: float | None = None  # ``takeoff_altitude: null``: each take-off node must give its altitude
    if not (f.has("takeoff_altitude") and f.raw("takeoff_altitude") is None):
        takeoff = f.number("takeoff_altitude", PROFILES[profile], positive=True)
    if alt_max is not None and takeoff is not None and takeoff > alt_max:
        raise f.error("takeoff_altitude", f"above altitude_max {alt_max:g}")
    sensors, range_sensor = _sensors(f)
    cap, percent, reserve = _battery(f)
    params = _autopilot_params(f)
    tasks = leaf_type_names()
    if f.has("tasks"):
        raw = f.raw("tasks")
        if not isinstance(raw, list) or not all(isinstance(t, str) for t in raw):
            raise f.error("tasks", "expected a list of task type names")
        for t in raw:
            if t not in leaf_type_names():
                raise f.error("tasks", f"unknown task type '{t}' (known: {', '.join(leaf_type_names())})")
        tasks = tuple(raw)
    sensor_profile = f.string("sensor_profile", "") or None
    return Platform(
        name=name, home=(home[0], home[1]), envelope=envelope, limits=limits,
        speeds=_options(f, "speeds", SPEED_NAMES, defaults.speeds),
        altitudes=_options(f, "altitudes", ALTITUDE_NAMES, defaults.altitudes),
        profile=profile, takeoff_altitude=takeoff, altitude_min=alt_min, altitude_max=alt_max,
        sensors=sensors, range_sensor=range_sensor, battery_capacity_s=cap, battery_percent=percent,
        reserve_s=reserve, autopilot_params=params, tasks=tasks, sensor_profile=sensor_profile,
        description=f.string("description", ""))


def _sensors(f: Fields) -> tuple[dict[str, Sensor], bool]:
    if not f.has("sensors"):
        return {"camera": Sensor()}, False
    s = f.sub("sensors")
    s.unknown((*SENSOR_TYPES, "range_sensor"))
    out: dict[str, Sensor] = {}
    for kind in SENSOR_TYPES:
        if not s.has(kind) or s.raw(kind) is False:
            continue
        spec = s.sub(kind, {}) if s.raw(kind) is not True else Fields({}, s.path(kind), s.file, s.line(kind))
        spec.unknown(("fov_deg", "overlap"))
        out[kind] = Sensor(kind, spec.number("fov_deg", 60.0, lo=1.0, hi=179.0),
                           spec.number("overlap", 0.2, lo=0.0, hi=0.95))
    return out, s.boolean("range_sensor", False)


def _battery(f: Fields) -> tuple[float, float, float]:
    if not f.has("battery"):
        return 900.0, 100.0, 0.0
    b = f.sub("battery")
    b.unknown(("capacity_s", "percent", "reserve_s"))
    cap = b.number("capacity_s", positive=True)
    reserve = b.number("reserve_s", 0.0, lo=0.0)
    if reserve >= cap:
        raise b.error("reserve_s", f"must be below capacity_s {cap:g}")
    return cap, b.number("percent", 100.0, lo=0.0, hi=100.0), reserve


def _autopilot_params(f: Fields) -> dict[str, float]:
    if not f.has("autopilot_params"):
        return {}
    p = f.sub("autopilot_params")
    out: dict[str, float] = {}
    for key in p.data:
        if not isinstance(key, str) or not key.replace("_", "").isalnum() or key.upper() != key:
            raise p.error(str(key), "an autopilot parameter name is upper case (e.g. WPNAV_SPEED)")
        out[key] = p.number(key, positive=key in BOUNDING_PARAMS)
    return out
