"""Airframe description (seed 002 Sec. 3.2: 'the airframe ... provide[s] a list of modules'; here in YAML).

:func:`load_airframe` validates every field and raises :class:`~taskflight_common.yamlio.ConfigError` naming
the file, the line and the field when something is wrong.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NotRequired, TypedDict

from autopilot_model.terrain import FLAT, Terrain, parse_terrain
from taskflight_common.yamlio import ConfigError, Fields, load_yaml

CONFIG_DIR = Path(__file__).parent / "config"
DEFAULT_AIRFRAME = CONFIG_DIR / "quad_x.yaml"
SENSOR_PROFILES = ("indoor", "outdoor", "perfect")


class EnvelopeLimits(TypedDict):
    """The flight envelope P_env of an airframe file (m, m/s, m/s^2, deg/s; a box or a polygon)."""

    max_speed_h: float
    max_speed_up: float
    max_speed_down: float
    max_accel_h: float
    max_accel_v: float
    max_yaw_rate: float
    alt_floor: float
    alt_ceiling: float
    box: NotRequired[Sequence[float]]
    polygon: NotRequired[Sequence[Sequence[float]]]


@dataclass
class Airframe:
    """Physical and configuration data of one vehicle type."""

    name: str
    mass: float
    inertia: tuple[float, float, float]
    arm_length: float
    thrust_max: float
    max_speed: float
    torque_ratio: float
    motor_tau: float
    spin_armed: float
    drag_linear: float
    drag_quadratic: float
    drag_rotational: float
    battery_cells: int
    battery_capacity_mah: float
    battery_r: float
    envelope: EnvelopeLimits
    sensors: str
    wind_mean: tuple[float, float, float]
    gust_sigma: float
    gust_max: float
    gust_tau: float
    gains: dict[str, float] = field(default_factory=dict)
    terrain: Terrain = FLAT
    """The ground under the vehicle (:mod:`autopilot_model.terrain`; flat by default)."""
    source: str = "<defaults>"

    @property
    def k_t(self) -> float:
        return self.thrust_max / self.max_speed**2

    @property
    def k_q(self) -> float:
        return self.k_t * self.torque_ratio


def load_airframe(path: str | Path | None = None) -> Airframe:
    """Read an airframe YAML file (the bundled Quad X when ``path`` is None)."""
    p = Path(path) if path is not None else DEFAULT_AIRFRAME
    data = load_yaml(p)
    f = Fields(data, file=str(p))
    f.unknown(("name", "frame", "mass", "inertia", "arm_length", "motors", "drag", "battery", "envelope",
               "sensors", "wind", "gains", "modules", "terrain"))
    frame = f.string("frame", "quad_x", choices=("quad_x",))
    del frame
    m = f.sub("motors")
    m.unknown(("thrust_max", "max_speed", "torque_ratio", "time_constant", "spin_armed"))
    d = f.sub("drag", {})
    d.unknown(("linear", "quadratic", "rotational"))
    b = f.sub("battery", {})
    b.unknown(("cells", "capacity_mah", "internal_resistance"))
    w = f.sub("wind", {})
    w.unknown(("mean", "gust_sigma", "gust_max", "gust_tau"))
    env = f.sub("envelope", {})
    env.unknown(("max_speed_h", "max_speed_up", "max_speed_down", "max_accel_h", "max_accel_v",
                 "max_yaw_rate", "alt_floor", "alt_ceiling", "box", "polygon"))
    envelope: EnvelopeLimits = {
        "max_speed_h": env.number("max_speed_h", 10.0, positive=True, hi=50.0),
        "max_speed_up": env.number("max_speed_up", 2.5, positive=True, hi=20.0),
        "max_speed_down": env.number("max_speed_down", 1.5, positive=True, hi=20.0),
        "max_accel_h": env.number("max_accel_h", 2.5, positive=True, hi=20.0),
        "max_accel_v": env.number("max_accel_v", 2.5, positive=True, hi=20.0),
        "max_yaw_rate": env.number("max_yaw_rate", 90.0, positive=True, hi=720.0),
        "alt_floor": env.number("alt_floor", -1000.0),
        "alt_ceiling": env.number("alt_ceiling", 120.0),
    }
    if envelope["alt_ceiling"] <= envelope["alt_floor"]:
        raise env.error("alt_ceiling", "must be above alt_floor")
    if env.has("box") and env.has("polygon"):
        raise env.error("polygon", "give either box or polygon, not both")
    if env.has("polygon"):
        poly = env.raw("polygon")
        if not isinstance(poly, list) or len(poly) < 3:
            raise env.error("polygon", "expected a list of at least 3 [north, east] points")
        pts = []
        for i, pt in enumerate(poly):
            if (not isinstance(pt, list) or len(pt) != 2
                    or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in pt)):
                line = poly.line_of(i) if hasattr(poly, "line_of") else env.line("polygon")
                raise ConfigError(env.file, line, env.path(f"polygon[{i}]"), "expected [north, east]")
            pts.append((float(pt[0]), float(pt[1])))
        envelope["polygon"] = pts
    else:
        box = env.vector("box", 4, [-2000.0, 2000.0, -2000.0, 2000.0])
        if box[0] >= box[1] or box[2] >= box[3]:
            raise env.error("box", "expected [north_min, north_max, east_min, east_max] with min < max")
        envelope["box"] = box
    gains_f = f.sub("gains", {})
    gains = {str(k): gains_f.number(str(k)) for k in gains_f.data}
    inertia = f.vector("inertia", 3)
    for i, v in enumerate(inertia):
        if v <= 0:
            raise f.error("inertia", f"component {i} must be > 0")
    af = Airframe(
        name=f.string("name", p.stem),
        mass=f.number("mass", positive=True, hi=100.0),
        inertia=inertia,  # type: ignore[arg-type]
        arm_length=f.number("arm_length", positive=True, hi=5.0),
        thrust_max=m.number("thrust_max", positive=True),
        max_speed=m.number("max_speed", positive=True),
        torque_ratio=m.number("torque_ratio", positive=True, hi=1.0),
        motor_tau=m.number("time_constant", lo=0.001, hi=1.0),
        spin_armed=m.number("spin_armed", 0.08, lo=0.0, hi=0.3),
        drag_linear=d.number("linear", 0.1, lo=0.0),
        drag_quadratic=d.number("quadratic", 0.05, lo=0.0),
        drag_rotational=d.number("rotational", 0.002, lo=0.0),
        battery_cells=b.integer("cells", 4, lo=1, hi=14),
        battery_capacity_mah=b.number("capacity_mah", 5000.0, positive=True),
        battery_r=b.number("internal_resistance", 0.02, lo=0.0),
        envelope=envelope,
        sensors=f.string("sensors", "outdoor", choices=SENSOR_PROFILES),
        wind_mean=w.vector("mean", 3, [0.0, 0.0, 0.0]),  # type: ignore[arg-type]
        gust_sigma=w.number("gust_sigma", 0.0, lo=0.0),
        gust_max=w.number("gust_max", 0.0, lo=0.0),
        gust_tau=w.number("gust_tau", 2.0, positive=True),
        gains=gains,
        terrain=parse_terrain(f.sub("terrain")) if f.has("terrain") else FLAT,
        source=str(p),
    )
    if 4 * af.thrust_max <= af.mass * 9.80665 * 1.2:
        raise f.error("motors", f"4 x thrust_max = {4 * af.thrust_max:g} N cannot lift {af.mass:g} kg "
                                "with a 20 % margin")
    return af
