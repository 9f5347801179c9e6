"""The ground the model flies over: a height field ``h(north, east)`` in metres above home's ground.

Seed 002 Fig. 4 puts the world (physics, sensors) beside the autopilot; the terrain is part of that world,
declared in the airframe YAML next to the wind (``terrain:``), flat when absent, so nothing else changes:

* ``hills``: a list of Gaussian hills ``{north, east, height, sigma}`` (m; height may be negative for a
  hollow), summed;
* ``grid``: heights on a regular grid, ``{north0, east0, spacing, heights: [[row north0], [row north0 +
  spacing], ...]}`` (each row along east), interpolated bilinearly; outside the grid the nearest edge
  value holds.

Both may be given (they add). Home's ground is the reference: heights are relative to it, and the
vehicle starts resting on the ground at home, ``h(0, 0)`` (0 unless a hill covers home).

Used by the physics for ground contact (the vehicle rests on ``h``, not on ``z = 0``) and by the
downward range finder (:mod:`autopilot_model.modules.rangefinder`). :func:`parse_terrain` validates
every field and raises :class:`~taskflight_common.yamlio.ConfigError` naming the file, line and field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from taskflight_common.yamlio import ConfigError, Fields


@dataclass(frozen=True)
class Hill:
    """A Gaussian hill: ``height * exp(-d^2 / (2 sigma^2))`` at distance ``d`` from (north, east)."""

    north: float
    east: float
    height: float
    sigma: float


@dataclass(frozen=True)
class Grid:
    """Heights on a regular grid (rows along north from ``north0``, columns along east from ``east0``)."""

    north0: float
    east0: float
    spacing: float
    heights: tuple[tuple[float, ...], ...]

    def height(self, north: float, east: float) -> float:
        rows, cols = len(self.heights), len(self.heights[0])
        fi = min(max((north - self.north0) / self.spacing, 0.0), rows - 1.0)
        fj = min(max((east - self.east0) / self.spacing, 0.0), cols - 1.0)
        i0, j0 = min(int(fi), rows - 2) if rows > 1 else 0, min(int(fj), cols - 2) if cols > 1 else 0
        i1, j1 = min(i0 + 1, rows - 1), min(j0 + 1, cols - 1)
        a, b = fi - i0, fj - j0
        h = self.heights
        return ((1 - a) * ((1 - b) * h[i0][j0] + b * h[i0][j1])
                + a * ((1 - b) * h[i1][j0] + b * h[i1][j1]))


@dataclass(frozen=True)
class Terrain:
    """The height field (flat when it has neither hills nor a grid)."""

    hills: tuple[Hill, ...] = ()
    grid: Grid | None = None
    source: str = field(default="<flat>", compare=False)

    @property
    def flat(self) -> bool:
        return not self.hills and self.grid is None

    def height(self, north: float, east: float) -> float:
        """Ground height (m above home's ground) at (north, east)."""
        h = 0.0
        for hill in self.hills:
            d2 = (north - hill.north) ** 2 + (east - hill.east) ** 2
            h += hill.height * math.exp(-d2 / (2.0 * hill.sigma * hill.sigma))
        if self.grid is not None:
            h += self.grid.height(north, east)
        return h


FLAT = Terrain()


def parse_terrain(f: Fields) -> Terrain:
    """The ``terrain:`` mapping of an airframe file (see module docstring)."""
    f.unknown(("hills", "grid"))
    hills: list[Hill] = []
    raw_hills = f.raw("hills", [])
    if not isinstance(raw_hills, list):
        raise f.error("hills", "expected a list of {north, east, height, sigma}")
    for i, item in enumerate(raw_hills):
        line = raw_hills.line_of(i) if hasattr(raw_hills, "line_of") else f.line("hills")
        h = Fields(item, f.path(f"hills[{i}]"), f.file, line)
        h.unknown(("north", "east", "height", "sigma"))
        hills.append(Hill(h.number("north"), h.number("east"), h.number("height", lo=-500.0, hi=500.0),
                          h.number("sigma", positive=True, hi=10000.0)))
    grid = None
    if f.has("grid"):
        g = f.sub("grid")
        g.unknown(("north0", "east0", "spacing", "heights"))
        rows = g.raw("heights")
        if not isinstance(rows, list) or not rows:
            raise g.error("heights", "expected a list of rows (each a list of heights in m)")
        width = None
        table: list[tuple[float, ...]] = []
        for i, row in enumerate(rows):
            line = rows.line_of(i) if hasattr(rows, "line_of") else g.line("heights")
            where = g.path(f"heights[{i}]")
            if not isinstance(row, list) or not row or not all(
                    isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in row):
                raise ConfigError(g.file, line, where, "expected a list of finite heights (m)")
            if width is not None and len(row) != width:
                raise ConfigError(g.file, line, where, f"has {len(row)} heights, row 0 has {width}")
            width = len(row)
            table.append(tuple(float(v) for v in row))
        grid = Grid(g.number("north0", 0.0), g.number("east0", 0.0), g.number("spacing", positive=True),
                    tuple(table))
    return Terrain(tuple(hills), grid, source=str(f.file))
