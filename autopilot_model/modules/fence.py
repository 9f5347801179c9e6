"""The geofence, as ArduPilot's ``AC_Fence`` (libraries/AC_Fence/AC_Fence.cpp) runs it in ArduCopter.

Parameters (ArduCopter names, units and defaults): FENCE_ENABLE, FENCE_TYPE (bits 1 max altitude, 2 circle
around home, 4 inclusion/exclusion polygons and circles of the FENCE plan, 8 min altitude, the floor),
FENCE_ACTION, FENCE_ALT_MAX, FENCE_ALT_MIN, FENCE_RADIUS, FENCE_MARGIN.

* *Enabled* fences are run-time state: FENCE_ENABLE 1 enables the configured types except the floor;
  MAV_CMD_DO_FENCE_ENABLE enables or disables types without changing FENCE_ENABLE (ArduPilot does not
  persist it either). The floor enables itself once the vehicle is FENCE_MARGIN above FENCE_ALT_MIN
  (with FENCE_ENABLE 1, or after a DO_FENCE_ENABLE that named it), and is disabled again while landing or
  landed unless it was enabled by hand.
* :meth:`Fence.check` returns the fence types *newly* breached. A breached type stays breached (no new
  breach) until the vehicle is back inside, unless it goes a further 20 m out (the backup fence, for
  the altitudes and the circle). Breaches are counted and timed for FENCE_STATUS.
* :meth:`Fence.destination_ok`: ArduCopter's ``check_destination_within_fence``, used for GUIDED targets.
* :meth:`Fence.prearm_failure`: ArduCopter's ``AC_Fence::pre_arm_check`` texts.
* FENCE_MARGIN is used where ArduCopter uses it: the pre-arm checks (``FENCE_MARGIN too big``, circle
  radius smaller than the margin), the floor's auto-enable height, and the margin-breach state reported
  by :attr:`Fence.margin_breached`.

The failsafe's response (RTL, LAND, BRAKE; LAND when more than 100 m outside) is in
:mod:`autopilot_model.modules.safety`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from shapely.geometry import Point, Polygon

from autopilot_model.modules.mission import (
    FENCE,
    FENCE_CIRCLE_EXCLUSION,
    FENCE_CIRCLE_INCLUSION,
    FENCE_POLYGON_EXCLUSION,
    FENCE_POLYGON_INCLUSION,
    MissionItem,
    MissionStore,
    vehicle_frames,
)
from taskflight_common.geo import geodetic_to_ned

if TYPE_CHECKING:
    from autopilot_model.modules.vehicle_api import VehicleApi
    from autopilot_model.params import ParamStore

ALT_MAX = 1
CIRCLE = 2
POLYGON = 4
ALT_MIN = 8
ARMING_FENCES = ALT_MAX | CIRCLE | POLYGON
ALL_FENCES = ARMING_FENCES | ALT_MIN
BACKUP_M = 20.0
"""After a breach the fence is re-created this much further out (ArduCopter's backup fence)."""
GIVE_UP_DISTANCE_M = 100.0
"""More than this outside the fence, ArduCopter lands instead of the configured action."""
NAMES = ((ALT_MAX, "Max Alt"), (CIRCLE, "Circle"), (POLYGON, "Polygon"), (ALT_MIN, "Min Alt"))

# MAV_CMD_DO_FENCE_ENABLE param1
DISABLE_FENCE = 0
ENABLE_FENCE = 1
DISABLE_ALT_MIN_FENCE = 2

# how the floor was last switched (AC_Fence::MinAltState)
_MIN_ALT_DEFAULT, _MIN_ALT_MANUALLY_ENABLED, _MIN_ALT_MANUALLY_DISABLED = 0, 1, 2


def fence_names(bits: int) -> str:
    """ArduPilot's ``get_fence_names``: "Max Alt fence", "Max Alt and Circle fences", ..."""
    names = [n for b, n in NAMES if bits & b]
    if not names:
        return ""
    text = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
    return text + (" fences" if len(names) > 1 else " fence")


def define_fence_params(params: ParamStore) -> None:
    """The FENCE_ parameters (ArduCopter names, ranges and defaults)."""
    params.define("FENCE_ENABLE", 0, 0, 1, "int", "geofence on (DO_FENCE_ENABLE does not change it)")
    params.define("FENCE_TYPE", 7, 0, 15, "int",
                  "fence bits: 1 max altitude, 2 circle around home, 4 polygons and circles, 8 min altitude")
    params.define("FENCE_ACTION", 1, 0, 5, "int",
                  "fence breach: 0 report, 1 RTL or LAND, 2 LAND, 3 SmartRTL/RTL, 4 BRAKE or LAND, "
                  "5 SmartRTL/LAND")
    params.define("FENCE_ALT_MAX", 100.0, 10.0, 1000.0, doc="maximum altitude above home (m)")
    params.define("FENCE_ALT_MIN", -10.0, -100.0, 100.0, doc="minimum altitude above home, the floor (m)")
    params.define("FENCE_RADIUS", 300.0, 30.0, 10000.0, doc="circular fence radius around home (m)")
    params.define("FENCE_MARGIN", 2.0, 1.0, 10.0,
                  doc="distance kept from the fence (m): pre-arm checks, floor auto-enable, margin breach")


class FenceShapes:
    """Inclusion/exclusion polygons and circles of the FENCE plan, in local NED (north, east)."""

    def __init__(self) -> None:
        self.inclusion: list[Polygon] = []
        self.exclusion: list[Polygon] = []
        self.inclusion_circles: list[tuple[float, float, float]] = []
        self.exclusion_circles: list[tuple[float, float, float]] = []

    @classmethod
    def from_items(cls, items: list[MissionItem], origin: tuple[float, float, float]) -> FenceShapes:
        shapes = cls()

        def ne(it: MissionItem) -> tuple[float, float]:
            n, e, _ = geodetic_to_ned(origin, it.lat, it.lon, origin[2])
            return float(n), float(e)

        i = 0
        while i < len(items):
            it = items[i]
            if it.command in (FENCE_POLYGON_INCLUSION, FENCE_POLYGON_EXCLUSION):
                n = int(it.param1)
                poly = Polygon([ne(v) for v in items[i:i + n]])
                (shapes.inclusion if it.command == FENCE_POLYGON_INCLUSION else shapes.exclusion).append(poly)
                i += n
                continue
            if it.command in (FENCE_CIRCLE_INCLUSION, FENCE_CIRCLE_EXCLUSION):
                circle = (*ne(it), float(it.param1))
                if it.command == FENCE_CIRCLE_INCLUSION:
                    shapes.inclusion_circles.append(circle)
                else:
                    shapes.exclusion_circles.append(circle)
            i += 1
        return shapes

    @property
    def empty(self) -> bool:
        return not (self.inclusion or self.exclusion or self.inclusion_circles or self.exclusion_circles)

    def outside_by(self, n: float, e: float) -> float:
        """How far (m) the point is on the wrong side of the nearest violated shape; <= 0: inside."""
        p = Point(n, e)
        worst = -math.inf
        for poly in self.inclusion:
            d = poly.exterior.distance(p)
            worst = max(worst, -d if poly.contains(p) else d)
        for poly in self.exclusion:
            d = poly.exterior.distance(p)
            worst = max(worst, d if poly.contains(p) else -d)
        for cn, ce, r in self.inclusion_circles:
            worst = max(worst, math.hypot(n - cn, e - ce) - r)
        for cn, ce, r in self.exclusion_circles:
            worst = max(worst, r - math.hypot(n - cn, e - ce))
        return worst


class Fence:
    """One vehicle's geofence state (see the module docstring). ``store`` gives the FENCE plan."""

    def __init__(self, vehicle: VehicleApi, store: MissionStore | None = None) -> None:
        self.vehicle = vehicle
        self.params = p = vehicle.params
        define_fence_params(p)
        self.store = store
        self.shapes = FenceShapes()
        self.enabled_fences = 0
        """Fence types enabled now (ArduPilot's ``_enabled_fences``)."""
        self.breached = 0
        """Fence types breached now."""
        self.margin_breached = 0
        self.breach_count = 0
        self.breach_time_ms = 0
        """Simulated time of the last breach (ms since boot), FENCE_STATUS.breach_time."""
        self.distance: dict[int, float] = {ALT_MAX: 0.0, ALT_MIN: 0.0, CIRCLE: 0.0, POLYGON: 0.0}
        self._backup: dict[int, float] = {ALT_MAX: 0.0, ALT_MIN: 0.0, CIRCLE: 0.0}
        self._min_alt_state = _MIN_ALT_DEFAULT
        self.floor_auto_enabled = False
        """Set when the floor enabled itself (the failsafe announces it and clears this)."""
        self._on_enable_param("FENCE_ENABLE", p.get("FENCE_ENABLE"))
        p.subscribe("FENCE_ENABLE", self._on_enable_param)
        if store is not None:
            store.on_change(self._on_plan_change)
            self._on_plan_change(FENCE)

    # --- configuration --------------------------------------------------------------------------
    def _on_enable_param(self, _name: str, value: float) -> None:
        """AC_Fence::update: a change of FENCE_ENABLE enables the configured fences but the floor."""
        self.enabled_fences = (self.configured & ~ALT_MIN) if value >= 1 else 0
        if not self.enabled_fences:
            self.breached = 0

    def _on_plan_change(self, mission_type: int) -> None:
        if mission_type != FENCE or self.store is None:
            return
        origin, _, _ = vehicle_frames(self.vehicle)
        self.shapes = FenceShapes.from_items(self.store.get(FENCE), origin)

    @property
    def configured(self) -> int:
        return int(self.params.get("FENCE_TYPE"))

    def present(self) -> int:
        """Configured types that exist (the polygon type only with a FENCE plan)."""
        mask = CIRCLE | ALT_MIN | ALT_MAX | (0 if self.shapes.empty else POLYGON)
        return self.configured & mask

    def enabled_now(self) -> int:
        return self.enabled_fences & self.present()

    @property
    def enabled(self) -> bool:
        """Any fence enabled (ArduPilot's ``AC_Fence::enabled``: FENCE_STATUS is sent only then)."""
        return bool(self.enabled_fences)

    def enable(self, value: bool, types: int = ALL_FENCES, manual: bool = True) -> int:
        """Enable or disable ``types`` (of those configured); returns the types that changed."""
        types &= self.configured
        new = (self.enabled_fences | types) if value else (self.enabled_fences & ~types)
        if manual and types & ALT_MIN:
            self._min_alt_state = _MIN_ALT_MANUALLY_ENABLED if value else _MIN_ALT_MANUALLY_DISABLED
        changed = self.enabled_fences ^ new
        self.enabled_fences = new
        if not value:
            self.breached &= ~changed
        return changed

    # --- geometry -------------------------------------------------------------------------------
    def _alt_and_home_distance(self, ned: tuple[float, float, float]) -> tuple[float, float]:
        _, _, home = vehicle_frames(self.vehicle)
        n, e, d = ned
        return -(d - home[2]), math.hypot(n - home[0], e - home[1])

    def destination_ok(self, ned: tuple[float, float, float]) -> bool:
        """ArduCopter's ``check_destination_within_fence`` for a target in local NED."""
        fences = self.enabled_now()
        if not fences:
            return True
        alt, dist = self._alt_and_home_distance(ned)
        if fences & ALT_MAX and alt > self.params.get("FENCE_ALT_MAX"):
            return False
        if fences & ALT_MIN and alt < self.params.get("FENCE_ALT_MIN"):
            return False
        if fences & CIRCLE and dist > self.params.get("FENCE_RADIUS"):
            return False
        return not (fences & POLYGON and self.shapes.outside_by(ned[0], ned[1]) > 0)

    # --- pre-arm --------------------------------------------------------------------------------
    def prearm_failure(self) -> str | None:
        """ArduCopter's ``AC_Fence::pre_arm_check``: the failure text, or None."""
        p = self.params
        if p.get("FENCE_ENABLE") >= 1 and not self.present():
            return "Fences enabled, but none selected"
        if not self.enabled or not self.configured:
            return None
        est = getattr(self.vehicle, "estimator", None)
        if self.configured & (CIRCLE | POLYGON) and est is not None and not est.initialised:
            return "Fence requires position"
        margin, alt_max, alt_min = p.get("FENCE_MARGIN"), p.get("FENCE_ALT_MAX"), p.get("FENCE_ALT_MIN")
        if self.configured & POLYGON:
            for _, _, r in self.shapes.inclusion_circles:
                if r < margin:
                    return "Polygon fence margin is greater than inclusion circle radius"
        if p.get("FENCE_RADIUS") < margin:
            return "Circle FENCE_MARGIN is greater than FENCE_RADIUS"
        if self.breached:
            return f"Vehicle breaching {fence_names(self.breached)}"
        if alt_max < alt_min:
            return "FENCE_ALT_MAX < FENCE_ALT_MIN"
        if alt_max - alt_min <= 2.0 * margin:
            return "FENCE_MARGIN too big"
        return None

    # --- the check ------------------------------------------------------------------------------
    def _auto_disable(self) -> int:
        """Types disabled while landing or landed (the floor, unless enabled by hand)."""
        return 0 if self._min_alt_state == _MIN_ALT_MANUALLY_ENABLED else ALT_MIN

    def check(self, landing_or_landed: bool) -> int:
        """``AC_Fence::check``: the fence types newly breached at the present position."""
        disabled = self._auto_disable() if landing_or_landed else 0
        self.breached &= self.configured
        self.margin_breached &= self.configured
        if disabled & self.enabled_fences:
            self.breached &= ~disabled
            self.margin_breached &= ~disabled
            self.enabled_fences &= ~disabled
        if not self.enabled and not self.configured & ALT_MIN:
            return 0
        ned = tuple(float(x) for x in self.vehicle.state.position_ned)
        alt, dist = self._alt_and_home_distance(ned)  # type: ignore[arg-type]
        margin = self.params.get("FENCE_MARGIN")
        new = 0
        fences = self.enabled_now()
        if fences & ALT_MAX:
            new |= self._check_level(ALT_MAX, alt - self.params.get("FENCE_ALT_MAX"), margin)
        if fences & ALT_MIN:
            new |= self._check_level(ALT_MIN, self.params.get("FENCE_ALT_MIN") - alt, margin)
        if not disabled & ALT_MIN:
            self._auto_enable_floor(alt, margin)
        if fences & CIRCLE:
            new |= self._check_level(CIRCLE, dist - self.params.get("FENCE_RADIUS"), margin)
        if fences & POLYGON:
            over = self.shapes.outside_by(ned[0], ned[1])
            self.distance[POLYGON] = over
            if over > 0:
                if not self.breached & POLYGON:
                    self._record_breach(POLYGON)
                    new |= POLYGON
            else:
                self.breached &= ~POLYGON
        else:
            self.breached &= ~POLYGON
        return new

    def _check_level(self, kind: int, over: float, margin: float) -> int:
        """One of the altitude or circle fences, ``over`` metres beyond it (< 0: inside)."""
        self.distance[kind] = over
        if over >= 0:
            backup = self._backup[kind]
            if not self.breached & kind or (backup and over >= backup):
                self._record_breach(kind)
                self._backup[kind] = over + BACKUP_M
                return kind
            return 0
        if over >= -margin:
            self.margin_breached |= kind
        else:
            self.margin_breached &= ~kind
        if self.breached & kind:
            self.breached &= ~kind
            self._backup[kind] = 0.0
        return 0

    def _auto_enable_floor(self, alt: float, margin: float) -> None:
        if (not self.configured & ALT_MIN or self.enabled_now() & ALT_MIN
                or self._min_alt_state == _MIN_ALT_MANUALLY_DISABLED or self.params.get("FENCE_ENABLE") < 1):
            return
        if alt >= self.params.get("FENCE_ALT_MIN") + margin:
            self.enabled_fences |= ALT_MIN
            self.floor_auto_enabled = True

    def _record_breach(self, kind: int) -> None:
        if not self.breached:
            self.breach_time_ms = int(self.vehicle.clock.now() * 1000)
        self.breach_count = min(self.breach_count + 1, 65500)
        self.breached |= kind

    def breach_distance(self, kinds: int) -> float:
        """The furthest distance (m) beyond the fences ``kinds`` (ArduPilot's ``get_breach_distance``)."""
        kinds &= self.present()
        return max((self.distance[k] for k, _ in NAMES if kinds & k), default=-math.inf)
