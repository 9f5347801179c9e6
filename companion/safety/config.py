"""The safety monitor's thresholds (:class:`SafetyConfig`), with defaults and a YAML form.

``taskflight companion --safety FILE`` reads a YAML mapping whose keys are the fields below (all optional;
an unknown key or a bad value is a :class:`~taskflight_common.yamlio.ConfigError` naming file, line and
field). ``--no-safety-monitor`` turns the monitor off (it says so at start). Actions: ``rtl`` (the RTL
behavior as the ``emergency`` requester, LAND if RTL is refused), ``land``, or ``report`` (tell the layers
above and the control surface, fly nothing: the autopilot already acts, or nothing reaches it).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import StrEnum
from pathlib import Path

from taskflight_common.yamlio import Fields, load_yaml


class Action(StrEnum):
    """What a trigger makes the monitor do, weakest first."""

    REPORT = "report"
    RTL = "rtl"
    LAND = "land"

    @property
    def severity(self) -> int:
        return {"report": 0, "rtl": 1, "land": 2}[self.value]


@dataclass(frozen=True)
class SafetyConfig:
    """Each trigger's threshold and action (see the module docstring and docs/companion.md)."""

    #: the monitor runs (False: ``--no-safety-monitor``)
    enabled: bool = True
    #: seconds of autopilot time between two checks
    period_s: float = 0.5
    # --- battery against the energy to get home ----------------------------------------------------------
    battery: bool = True
    #: the pack's capacity (mAh); None: derived from BATTERY_STATUS's consumed mAh and the remaining percent
    battery_capacity_mah: float | None = None
    #: act when the charge left is below the charge the return needs times this margin
    battery_margin: float = 1.5
    #: the return's speeds (m/s): None cruise is the queue's horizontal speed limit
    cruise_speed: float | None = None
    descent_speed: float = 1.0
    battery_action: Action = Action.RTL
    #: the charge left cannot even cover the return (margin 1): this action
    battery_critical_action: Action = Action.LAND
    # --- the autopilot's estimate (EKF) ------------------------------------------------------------------
    estimate: bool = True
    #: the AHRS health bit (SYS_STATUS) off this long while flying
    estimate_unhealthy_s: float = 2.0
    estimate_action: Action = Action.LAND
    # --- the link to the autopilot -----------------------------------------------------------------------
    link: bool = True
    #: wall seconds the autopilot stays unheard beyond the link's own time-out (3 s) before it counts as lost
    link_lost_s: float = 5.0
    link_action: Action = Action.REPORT
    # --- the autopilot's own failsafe (it switched itself to RTL, LAND, SMART_RTL, BRAKE) -------------------
    autopilot_failsafe: bool = True
    autopilot_failsafe_action: Action = Action.REPORT
    # --- the fence ahead ---------------------------------------------------------------------------------
    fence: bool = True
    #: the point where the vehicle would stop (braking at the queue's horizontal acceleration) lies this far
    #: beyond the envelope, or the autopilot reports its own geofence breached
    fence_margin_m: float = 2.0
    fence_action: Action = Action.RTL
    #: RTL's lowest return altitude (m above home; None: the current altitude), held inside the envelope
    rtl_altitude: float | None = None

    def __post_init__(self) -> None:
        for name in ("period_s", "battery_margin", "descent_speed", "estimate_unhealthy_s", "link_lost_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"safety.{name}: must be > 0, got {getattr(self, name)}")
        for name in ("battery_capacity_mah", "cruise_speed", "rtl_altitude"):
            value = getattr(self, name)
            if value is not None and not value > 0:
                raise ValueError(f"safety.{name}: must be > 0, got {value}")
        if self.fence_margin_m < 0:
            raise ValueError(f"safety.fence_margin_m: must be >= 0, got {self.fence_margin_m}")

    def thresholds(self) -> dict[str, object]:
        """Every field, as the control surface shows them."""
        out: dict[str, object] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            out[f.name] = value.value if isinstance(value, Action) else value
        return out


def load_safety_config(path: str | Path) -> SafetyConfig:
    """A :class:`SafetyConfig` from a YAML mapping of its fields (ConfigError naming file:line: field)."""
    data = load_yaml(path)
    if data is None:
        return SafetyConfig()
    f = Fields(data, "", str(path))
    known = {x.name: x for x in fields(SafetyConfig)}
    f.unknown(known)
    kw: dict[str, object] = {}
    for name in f.data:
        default = getattr(SafetyConfig, name)
        if isinstance(default, bool):
            kw[name] = f.boolean(name)
        elif isinstance(default, Action):
            kw[name] = Action(f.string(name, choices=[a.value for a in Action]))
        elif f.raw(name) is None and name in ("battery_capacity_mah", "cruise_speed", "rtl_altitude"):
            kw[name] = None
        else:
            kw[name] = f.number(name, positive=name != "fence_margin_m", lo=0.0)
    return SafetyConfig(**kw)  # type: ignore[arg-type]
