"""Flight commands: three control channels plus an end condition (seed 000 Sec. IV-A, Fig. 7, Fig. 8).

A :class:`FlightCommand` has a *horizontal*, a *vertical* and a *heading* channel, each in one mode
with that mode's parameters (Fig. 7), and an :class:`EndCondition` (Fig. 8). Commands are immutable
and validated when built: a command that could never end, or whose modes contradict each other, is
refused with a :class:`CommandError` naming the field and the reason.

Units and frames
    Positions are local NED metres relative to the autopilot's origin (home); *altitude* is metres
    up (``-down``). Every angle a command carries (heading, offsets, rates) is in **degrees** and
    degrees per second, as an operator writes them (the paper's "offset of 180 degrees"); the
    references and setpoints the queue produces are in radians, as MAVLink wants them.

Decisions where the paper is silent (documented once here)
    * ``speed`` left out (``None``) means "as fast as the :class:`~companion.flight.limits.Limits`
      allow"; a given speed must be > 0 and is capped by the limits; ``end_speed`` must lie in
      ``[0, speed]``.
    * Body-relative horizontal positions: ``north`` is *forward* and ``east`` is *right* of the
      heading the reference has when the command starts.
    * Relative targets (horizontal, vertical, heading) are resolved once, when the command first
      starts, against the reference at that moment; a command resumed after a pause keeps them.
    * Speed modifiers (Fig. 7, column "Modifiers" of *speed*): ``speed_modified_by`` lists the
      channels allowed to *slow this channel down so that the channels arrive together*. The
      horizontal speed may be modified by ``vertical`` (V_sm of V_Pos / V_ExtPos) and by ``heading``
      (Hd_sm of Hd_Pos / Hd_ExtPos: arrive together; of Hd_FlightDir: the horizontal speed is
      scaled by ``cos`` of the heading error, so the vehicle turns into its flight direction before
      it speeds up). The vertical speed may be modified by ``heading`` (Hd_Pos / Hd_ExtPos). A
      modifier naming a channel whose mode produces no speed modifier is refused.
    * ``V_WithHor`` flies the straight 3-D line to (north, east, altitude); its altitude is
      absolute; the horizontal ``speed`` stays the horizontal speed (the vertical component follows
      and, when the vertical limit binds, the whole line slows down). V_end equals H_end.
    * RC velocity modes (``RC_VEL``): the channel's velocity is the pilot's stick, read from the
      autopilot's RC_CHANNELS by the link (:mod:`companion.link.rc`: deadband, scale to the limits,
      sticks relative to the vehicle's heading) and stored as the external stream ``rc_vel``; they
      behave exactly as the corresponding ExtVel mode fed from that stream. With no fresh
      ``rc_vel`` sample (no RC, no signal) the channel's velocity is zero, like any stale stream.
    * ``DNU`` ("do not use"): the channel's setpoint stays constant. If it was moving when the
      command started, it first comes to rest within the limits (never a jump) and then holds.
    * ``take_off`` needs ``V_Pos`` climbing (a relative altitude must be > 0); ``allow_landing``
      needs ``V_Pos`` descending (a relative altitude must be < 0); the two exclude each other.
    * ``Hd_Pos`` with ``stop_at_heading = false`` keeps yawing at ``rate``; its Hd_end is raised
      (and stays raised) once the reference has passed the heading.

End condition (Fig. 8): the channel element, E_User and E_Wait are a conjunction. Within the
channel element, the selected flags E_H, E_V, E_Hd must all be raised; with E_Any, one of them
suffices (E_Any alone: any channel able to raise an end flag). A command refused as "can never end":
no element at all; E_H / E_V / E_Hd on a channel whose mode never raises that flag (DNU, ExtVel,
RCVel, and for heading also FlightDir); E_Any with no channel able to raise a flag.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from enum import Enum
from typing import Any


class CommandError(ValueError):
    """A flight command is invalid; ``field`` is the dotted path of the offending field."""

    def __init__(self, field: str, reason: str) -> None:
        self.field = field
        self.reason = reason
        super().__init__(f"{field}: {reason}")


class HorizontalMode(Enum):
    """Horizontal channel modes (Fig. 7a)."""

    POS = "POS"
    EXT_POS = "EXT_POS"
    KEEP_DISTANCE = "KEEP_DISTANCE"
    EXT_VEL = "EXT_VEL"
    RC_VEL = "RC_VEL"
    DNU = "DNU"


class VerticalMode(Enum):
    """Vertical channel modes (Fig. 7b)."""

    POS = "POS"
    WITH_HOR = "WITH_HOR"
    EXT_POS = "EXT_POS"
    EXT_VEL = "EXT_VEL"
    RC_VEL = "RC_VEL"
    DNU = "DNU"
    GROUND = "GROUND"
    """Ours, for Fig. 12a / 14a's ``follow_ground_flag``: hold ``altitude`` metres above the ground the
    downward range finder measures (:mod:`.execution`)."""


class HeadingMode(Enum):
    """Heading channel modes (Fig. 7c)."""

    POS = "POS"
    FLIGHT_DIR = "FLIGHT_DIR"
    EXT_POS = "EXT_POS"
    EXT_VEL = "EXT_VEL"
    RC_VEL = "RC_VEL"
    POINT = "POINT"
    EXT_POINT = "EXT_POINT"
    DNU = "DNU"


class Frame(Enum):
    """How a position / altitude / heading parameter is meant (Fig. 7 "Modifiers")."""

    ABSOLUTE = "absolute"
    RELATIVE = "relative"
    BODY_RELATIVE = "body_relative"


class SpeedModifier(Enum):
    """A channel allowed to slow another one down (Fig. 7: V_sm, Hd_sm)."""

    VERTICAL = "vertical"
    HEADING = "heading"


#: Modes whose channel raises an end flag (Fig. 7, column "Output").
H_END_MODES = frozenset({HorizontalMode.POS, HorizontalMode.EXT_POS, HorizontalMode.KEEP_DISTANCE})
V_END_MODES = frozenset({VerticalMode.POS, VerticalMode.WITH_HOR, VerticalMode.EXT_POS, VerticalMode.GROUND})
HD_END_MODES = frozenset({HeadingMode.POS, HeadingMode.EXT_POS, HeadingMode.POINT, HeadingMode.EXT_POINT})
#: Velocity-type modes (streamed, not planned to a target).
H_VEL_MODES = frozenset({HorizontalMode.EXT_VEL, HorizontalMode.RC_VEL})
V_VEL_MODES = frozenset({VerticalMode.EXT_VEL, VerticalMode.RC_VEL})

_H_PARAMS: dict[HorizontalMode, frozenset[str]] = {
    HorizontalMode.POS: frozenset({"north", "east", "frame", "speed", "end_speed", "speed_modified_by"}),
    HorizontalMode.EXT_POS: frozenset({"offset_north", "offset_east", "speed", "speed_modified_by"}),
    HorizontalMode.KEEP_DISTANCE: frozenset({"distance", "speed", "speed_modified_by"}),
    HorizontalMode.EXT_VEL: frozenset(),
    HorizontalMode.RC_VEL: frozenset(),
    HorizontalMode.DNU: frozenset(),
}
_H_REQUIRED = {HorizontalMode.POS: ("north", "east"), HorizontalMode.KEEP_DISTANCE: ("distance",)}

_V_PARAMS: dict[VerticalMode, frozenset[str]] = {
    VerticalMode.POS: frozenset({"altitude", "frame", "speed", "end_speed", "speed_modified_by"}),
    VerticalMode.WITH_HOR: frozenset({"altitude"}),
    VerticalMode.EXT_POS: frozenset({"offset", "speed", "speed_modified_by"}),
    VerticalMode.EXT_VEL: frozenset(),
    VerticalMode.RC_VEL: frozenset(),
    VerticalMode.DNU: frozenset(),
    VerticalMode.GROUND: frozenset({"altitude", "speed"}),
}
_V_REQUIRED = {VerticalMode.POS: ("altitude",), VerticalMode.WITH_HOR: ("altitude",),
               VerticalMode.GROUND: ("altitude",)}

_HD_PARAMS: dict[HeadingMode, frozenset[str]] = {
    HeadingMode.POS: frozenset({"heading", "frame", "rate", "stop_at_heading", "use_sign"}),
    HeadingMode.FLIGHT_DIR: frozenset({"offset", "rate"}),
    HeadingMode.EXT_POS: frozenset({"offset", "speed"}),
    HeadingMode.EXT_VEL: frozenset(),
    HeadingMode.RC_VEL: frozenset(),
    HeadingMode.POINT: frozenset({"north", "east", "offset", "rate"}),
    HeadingMode.EXT_POINT: frozenset({"offset"}),
    HeadingMode.DNU: frozenset(),
}
_HD_REQUIRED = {HeadingMode.POS: ("heading",), HeadingMode.POINT: ("north", "east")}


# --- small validation helpers ------------------------------------------------------------------
def _coerce_enum(enum_cls: type[Enum], value: Any, where: str) -> Any:
    if isinstance(value, enum_cls):
        return value
    if isinstance(value, str):
        for member in enum_cls:
            if value.strip().upper() == member.name or value.strip().lower() == str(member.value).lower():
                return member
    allowed = ", ".join(m.name for m in enum_cls)
    raise CommandError(where, f"unknown value {value!r} (allowed: {allowed})")


def _check_number(where: str, value: Any, *, positive: bool = False, nonneg: bool = False,
                  nonzero: bool = False) -> None:
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise CommandError(where, f"expected a number, got {value!r}")
    if not math.isfinite(value):
        raise CommandError(where, f"must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise CommandError(where, f"must be > 0, got {value:g}")
    if nonneg and value < 0:
        raise CommandError(where, f"must be >= 0, got {value:g}")
    if nonzero and value == 0:
        raise CommandError(where, "must not be 0")


def _check_bool(where: str, value: Any) -> None:
    if value is not None and not isinstance(value, bool):
        raise CommandError(where, f"expected true or false, got {value!r}")


def _check_params(prefix: str, channel: Any, mode: Enum, allowed: frozenset[str],
                  required: tuple[str, ...]) -> None:
    """Refuse parameters that do not belong to ``mode`` and require the mandatory ones."""
    for f in fields(channel):
        if f.name in ("mode", "take_off", "allow_landing"):
            continue
        value = getattr(channel, f.name)
        is_set = value not in (None, ())
        if is_set and f.name not in allowed:
            raise CommandError(f"{prefix}.{f.name}", f"not a parameter of {prefix} mode {mode.name}")
    for name in required:
        if getattr(channel, name) is None:
            raise CommandError(f"{prefix}.{name}", f"required by {prefix} mode {mode.name}")


def _coerce_modifiers(value: Any, where: str) -> tuple[SpeedModifier, ...]:
    if value is None:
        return ()
    if isinstance(value, str | SpeedModifier):
        value = (value,)
    if not isinstance(value, list | tuple | set | frozenset):
        raise CommandError(where, f"expected a list of channel names, got {value!r}")
    out: list[SpeedModifier] = []
    for item in value:
        mod = _coerce_enum(SpeedModifier, item, where)
        if mod in out:
            raise CommandError(where, f"'{mod.value}' listed twice")
        out.append(mod)
    return tuple(sorted(out, key=lambda m: m.value))


# --- channels ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class HorizontalChannel:
    """Horizontal channel (Fig. 7a). Parameters not used by ``mode`` must stay ``None``.

    POS: ``north``, ``east`` (m), ``frame`` (absolute | relative | body_relative; default absolute),
    ``speed`` (m/s), ``end_speed`` (m/s, default 0), ``speed_modified_by``.
    EXT_POS: ``offset_north``, ``offset_east`` (m, default 0), ``speed``, ``speed_modified_by``.
    KEEP_DISTANCE: ``distance`` (m, > 0), ``speed``, ``speed_modified_by``.
    EXT_VEL, RC_VEL, DNU: no parameters.
    """

    mode: HorizontalMode = HorizontalMode.DNU
    north: float | None = None
    east: float | None = None
    frame: Frame | None = None
    speed: float | None = None
    end_speed: float | None = None
    offset_north: float | None = None
    offset_east: float | None = None
    distance: float | None = None
    speed_modified_by: tuple[SpeedModifier, ...] = ()

    def __post_init__(self) -> None:
        p = "horizontal"
        object.__setattr__(self, "mode", _coerce_enum(HorizontalMode, self.mode, f"{p}.mode"))
        if self.frame is not None:
            object.__setattr__(self, "frame", _coerce_enum(Frame, self.frame, f"{p}.frame"))
        object.__setattr__(self, "speed_modified_by",
                           _coerce_modifiers(self.speed_modified_by, f"{p}.speed_modified_by"))
        for name in ("north", "east", "offset_north", "offset_east"):
            _check_number(f"{p}.{name}", getattr(self, name))
        _check_number(f"{p}.speed", self.speed, positive=True)
        _check_number(f"{p}.end_speed", self.end_speed, nonneg=True)
        _check_number(f"{p}.distance", self.distance, positive=True)
        _check_params(p, self, self.mode, _H_PARAMS[self.mode], _H_REQUIRED.get(self.mode, ()))
        if self.speed is not None and self.end_speed is not None and self.end_speed > self.speed:
            raise CommandError(f"{p}.end_speed",
                               f"must not exceed speed ({self.end_speed:g} > {self.speed:g})")

    @property
    def resolved_frame(self) -> Frame:
        return self.frame or Frame.ABSOLUTE


@dataclass(frozen=True)
class VerticalChannel:
    """Vertical channel (Fig. 7b) with the *take-off* and *allow landing* flags (Sec. IV-A2).

    POS: ``altitude`` (m up), ``frame`` (absolute | relative; default absolute), ``speed``,
    ``end_speed``, ``speed_modified_by`` (``heading`` only).
    WITH_HOR: ``altitude`` (absolute). EXT_POS: ``offset`` (m above the external target), ``speed``,
    ``speed_modified_by``. GROUND: ``altitude`` (m above the ground under the vehicle, > 0), ``speed``.
    EXT_VEL, RC_VEL, DNU: no parameters.
    """

    mode: VerticalMode = VerticalMode.DNU
    altitude: float | None = None
    frame: Frame | None = None
    speed: float | None = None
    end_speed: float | None = None
    offset: float | None = None
    speed_modified_by: tuple[SpeedModifier, ...] = ()
    take_off: bool = False
    allow_landing: bool = False

    def __post_init__(self) -> None:
        p = "vertical"
        object.__setattr__(self, "mode", _coerce_enum(VerticalMode, self.mode, f"{p}.mode"))
        if self.frame is not None:
            frame = _coerce_enum(Frame, self.frame, f"{p}.frame")
            if frame is Frame.BODY_RELATIVE:
                raise CommandError(f"{p}.frame", "the vertical channel is absolute or relative only")
            object.__setattr__(self, "frame", frame)
        object.__setattr__(self, "speed_modified_by",
                           _coerce_modifiers(self.speed_modified_by, f"{p}.speed_modified_by"))
        _check_number(f"{p}.altitude", self.altitude)
        _check_number(f"{p}.offset", self.offset)
        _check_number(f"{p}.speed", self.speed, positive=True)
        _check_number(f"{p}.end_speed", self.end_speed, nonneg=True)
        _check_bool(f"{p}.take_off", self.take_off)
        _check_bool(f"{p}.allow_landing", self.allow_landing)
        _check_params(p, self, self.mode, _V_PARAMS[self.mode], _V_REQUIRED.get(self.mode, ()))
        if self.mode is VerticalMode.GROUND and self.altitude is not None and self.altitude <= 0:
            raise CommandError(f"{p}.altitude", f"height above the ground must be > 0, got {self.altitude:g}")
        if SpeedModifier.VERTICAL in self.speed_modified_by:
            raise CommandError(f"{p}.speed_modified_by", "the vertical channel cannot modify itself")
        if self.speed is not None and self.end_speed is not None and self.end_speed > self.speed:
            raise CommandError(f"{p}.end_speed",
                               f"must not exceed speed ({self.end_speed:g} > {self.speed:g})")
        if self.take_off and self.allow_landing:
            raise CommandError(f"{p}.take_off", "a command cannot be both a take-off and a landing")
        for flag in ("take_off", "allow_landing"):
            if getattr(self, flag) and self.mode is not VerticalMode.POS:
                raise CommandError(f"{p}.{flag}", f"needs vertical mode POS, not {self.mode.name}")
        if self.mode is VerticalMode.POS and self.resolved_frame is Frame.RELATIVE:
            assert self.altitude is not None
            if self.take_off and self.altitude <= 0:
                raise CommandError(f"{p}.altitude", "a take-off must climb (relative altitude > 0)")
            if self.allow_landing and self.altitude >= 0:
                raise CommandError(f"{p}.altitude", "a landing must descend (relative altitude < 0)")

    @property
    def resolved_frame(self) -> Frame:
        return self.frame or Frame.ABSOLUTE


@dataclass(frozen=True)
class HeadingChannel:
    """Heading channel (Fig. 7c). Angles in degrees, rates in degrees per second.

    POS: ``heading``, ``frame`` (absolute | relative), ``rate``, ``stop_at_heading`` (default true),
    ``use_sign`` (default false: the rate's sign is ignored and the shorter way is taken).
    FLIGHT_DIR: ``offset``, ``rate``. EXT_POS: ``offset``, ``speed`` (deg/s).
    POINT: ``north``, ``east`` (m), ``offset``, ``rate``. EXT_POINT: ``offset``.
    EXT_VEL, RC_VEL, DNU: no parameters.
    """

    mode: HeadingMode = HeadingMode.DNU
    heading: float | None = None
    frame: Frame | None = None
    rate: float | None = None
    stop_at_heading: bool | None = None
    use_sign: bool | None = None
    offset: float | None = None
    speed: float | None = None
    north: float | None = None
    east: float | None = None

    def __post_init__(self) -> None:
        p = "heading"
        object.__setattr__(self, "mode", _coerce_enum(HeadingMode, self.mode, f"{p}.mode"))
        if self.frame is not None:
            frame = _coerce_enum(Frame, self.frame, f"{p}.frame")
            if frame is Frame.BODY_RELATIVE:
                raise CommandError(f"{p}.frame", "the heading channel is absolute or relative only")
            object.__setattr__(self, "frame", frame)
        for name in ("heading", "offset", "north", "east"):
            _check_number(f"{p}.{name}", getattr(self, name))
        _check_number(f"{p}.rate", self.rate, nonzero=True)
        _check_number(f"{p}.speed", self.speed, positive=True)
        _check_bool(f"{p}.stop_at_heading", self.stop_at_heading)
        _check_bool(f"{p}.use_sign", self.use_sign)
        _check_params(p, self, self.mode, _HD_PARAMS[self.mode], _HD_REQUIRED.get(self.mode, ()))
        # In POS a negative rate is meaningful with use_sign (rotate the negative way); elsewhere not.
        if self.mode is not HeadingMode.POS and self.rate is not None and self.rate < 0:
            raise CommandError(f"{p}.rate", f"must be > 0 in heading mode {self.mode.name}")

    @property
    def resolved_frame(self) -> Frame:
        return self.frame or Frame.ABSOLUTE

    @property
    def stops(self) -> bool:
        """``stop_at_heading`` with its default (true)."""
        return True if self.stop_at_heading is None else self.stop_at_heading


@dataclass(frozen=True)
class EndCondition:
    """Fig. 8: channel flags (E_H, E_V, E_Hd, or E_Any), user confirmation E_User, timeout E_Wait (s).

    The three kinds of element are a conjunction; see the module docstring for E_Any. A command
    whose only element is ``e_wait`` is a pause (Sec. IV-A4).
    """

    e_h: bool = False
    e_v: bool = False
    e_hd: bool = False
    e_any: bool = False
    e_user: bool = False
    e_wait: float | None = None

    def __post_init__(self) -> None:
        for name in ("e_h", "e_v", "e_hd", "e_any", "e_user"):
            value = getattr(self, name)
            if not isinstance(value, bool):
                raise CommandError(f"end.{name}", f"expected true or false, got {value!r}")
        _check_number("end.e_wait", self.e_wait, nonneg=True)
        if not (self.e_h or self.e_v or self.e_hd or self.e_any or self.e_user or self.e_wait is not None):
            raise CommandError("end", "no end condition: the command could never end "
                                      "(give e_h, e_v, e_hd, e_any, e_user or e_wait)")

    @property
    def uses_channels(self) -> bool:
        return self.e_h or self.e_v or self.e_hd or self.e_any


def _default_end() -> EndCondition:
    return EndCondition(e_user=True)


@dataclass(frozen=True)
class FlightCommand:
    """One flight command (Sec. IV-A): horizontal, vertical and heading channels and an end condition.

    The default end condition is E_User (the command runs until the operator confirms), so a bare
    ``FlightCommand()`` is a hover that waits for ``user_confirm``.
    """

    horizontal: HorizontalChannel = field(default_factory=HorizontalChannel)
    vertical: VerticalChannel = field(default_factory=VerticalChannel)
    heading: HeadingChannel = field(default_factory=HeadingChannel)
    end: EndCondition = field(default_factory=_default_end)

    def __post_init__(self) -> None:
        for name, cls in (("horizontal", HorizontalChannel), ("vertical", VerticalChannel),
                          ("heading", HeadingChannel), ("end", EndCondition)):
            if not isinstance(getattr(self, name), cls):
                got = type(getattr(self, name)).__name__
                raise CommandError(name, f"expected a {cls.__name__}, got {got}")
        self._check_modes()
        self._check_modifiers()
        self._check_end()

    # --- cross-channel rules ---------------------------------------------------------------------
    def _check_modes(self) -> None:
        h, v = self.horizontal, self.vertical
        if v.mode is VerticalMode.WITH_HOR and h.mode is not HorizontalMode.POS:
            raise CommandError("vertical.mode",
                               f"WITH_HOR extends horizontal POS, but horizontal is {h.mode.name}")

    def _check_modifiers(self) -> None:
        h, v, hd = self.horizontal, self.vertical, self.heading
        heading_sm = hd.mode in (HeadingMode.POS, HeadingMode.EXT_POS, HeadingMode.FLIGHT_DIR)
        if hd.mode is HeadingMode.POS and not hd.stops:
            heading_sm = False
        for mod in h.speed_modified_by:
            if mod is SpeedModifier.VERTICAL and v.mode not in (VerticalMode.POS, VerticalMode.EXT_POS):
                raise CommandError("horizontal.speed_modified_by",
                                   f"vertical mode {v.mode.name} gives no speed modifier "
                                   "(needs POS or EXT_POS)")
            if mod is SpeedModifier.HEADING and not heading_sm:
                raise CommandError("horizontal.speed_modified_by",
                                   f"heading mode {hd.mode.name} gives no speed modifier "
                                   "(needs POS stopping at the heading, EXT_POS or FLIGHT_DIR)")
        for mod in v.speed_modified_by:
            if mod is SpeedModifier.HEADING and (not heading_sm or hd.mode is HeadingMode.FLIGHT_DIR):
                raise CommandError("vertical.speed_modified_by",
                                   f"heading mode {hd.mode.name} gives no vertical speed modifier "
                                   "(needs POS stopping at the heading or EXT_POS)")

    def _check_end(self) -> None:
        e = self.end
        capable = {"e_h": self.horizontal.mode in H_END_MODES,
                   "e_v": self.vertical.mode in V_END_MODES,
                   "e_hd": self.heading.mode in HD_END_MODES}
        modes = {"e_h": ("horizontal", self.horizontal.mode), "e_v": ("vertical", self.vertical.mode),
                 "e_hd": ("heading", self.heading.mode)}
        selected = [name for name in ("e_h", "e_v", "e_hd") if getattr(e, name)]
        if not e.e_any:
            for name in selected:
                if not capable[name]:
                    channel, mode = modes[name]
                    raise CommandError(f"end.{name}", f"{channel} mode {mode.name} never raises its end "
                                                      "flag: the command could never end")
        else:
            pool = selected or ["e_h", "e_v", "e_hd"]
            if not any(capable[name] for name in pool):
                raise CommandError("end.e_any", "none of the channels can raise an end flag: "
                                                "the command could never end")

    # --- conveniences ------------------------------------------------------------------------------
    @property
    def is_pause(self) -> bool:
        """True for a command with only E_Wait (Sec. IV-A4: it "effectively becomes a pause")."""
        e = self.end
        return e.e_wait is not None and not (e.uses_channels or e.e_user)

    @property
    def velocity_only(self) -> bool:
        """True when both motion channels are velocity streams (the link may send velocity only)."""
        return self.horizontal.mode in H_VEL_MODES and self.vertical.mode in V_VEL_MODES
