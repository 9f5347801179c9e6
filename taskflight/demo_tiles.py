"""An offline tile set of the demo's area, drawn here (no download): a small MBTiles file for the map.

``taskflight up`` makes ``<state-dir>/tiles.mbtiles`` around its platform's home at its first run and
gives it to the ground service (``taskflight ground --tiles``), so the first run already shows a map.
The tiles are plain raster PNGs drawn with PIL in Web Mercator (EPSG:3857, XYZ tiles stored with the
TMS row numbering MBTiles uses, :mod:`groundstation.tiles`): a terrain-coloured ground (a smooth
deterministic field of grass and dry earth), a grid of 100 m (10 m at the closest zooms) from home with
its distances labelled, and the home pad. They are not a survey: they give the operator scale and
orientation offline. ``python -m taskflight.demo_tiles OUT.mbtiles LAT LON`` makes one anywhere.
"""

from __future__ import annotations

import io
import logging
import math
import sqlite3
import sys
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from taskflight_common.geo import LOCATION_SCALING_FACTOR, geodetic_to_ned

log = logging.getLogger(__name__)

TILE = 256
DEFAULT_ZOOMS = range(14, 19)
DEFAULT_RADIUS_M = 400.0
M_PER_DEG = LOCATION_SCALING_FACTOR * 1e7


def tile_of(lat: float, lon: float, z: int) -> tuple[float, float]:
    """The fractional XYZ tile (x, y) of (lat, lon) at zoom ``z`` (Web Mercator)."""
    n = 2 ** z
    s = math.sin(math.radians(lat))
    return (lon + 180.0) / 360.0 * n, (0.5 - math.log((1 + s) / (1 - s)) / (4 * math.pi)) * n


def lonlat_of(x: float, y: float, z: int) -> tuple[float, float]:
    """(lat, lon) of the fractional XYZ tile position (x, y) at zoom ``z``."""
    n = 2 ** z
    lat = math.degrees(math.atan(math.sinh(math.pi * (1 - 2 * y / n))))
    return lat, x / n * 360.0 - 180.0


def _ground(north: np.ndarray, east: np.ndarray) -> np.ndarray:
    """RGB of the terrain at (north, east) metres from home: grass with patches of dry earth."""
    f = (np.sin(north / 61.0) * np.cos(east / 47.0) + 0.6 * np.sin((north + east) / 113.0)
         + 0.35 * np.cos((north - 2 * east) / 29.0))
    t = np.clip((f + 1.2) / 2.4, 0.0, 1.0)[..., None]
    grass, earth = np.array([126, 158, 92], float), np.array([196, 178, 128], float)
    return (grass * (1 - t) + earth * t).astype(np.uint8)


def draw_tile(z: int, x: int, y: int, home: tuple[float, float]) -> bytes:
    """The PNG of tile ``z/x/y`` around ``home`` (lat, lon)."""
    origin = (home[0], home[1], 0.0)
    k = 32  # the terrain field at 32 x 32, smoothed up to 256 x 256
    us = x + (np.arange(k) + 0.5) / k
    vs = y + (np.arange(k) + 0.5) / k
    lats = np.degrees(np.arctan(np.sinh(np.pi * (1 - 2 * vs / 2 ** z))))
    lons = us / 2 ** z * 360.0 - 180.0
    north = ((lats - home[0]) * M_PER_DEG)[:, None].repeat(k, 1)
    east = ((lons - home[1]) * M_PER_DEG * math.cos(math.radians(home[0])))[None, :].repeat(k, 0)
    img = Image.fromarray(_ground(north, east), "RGB").resize((TILE, TILE), Image.Resampling.BILINEAR)
    d = ImageDraw.Draw(img)

    def px(lat: float, lon: float) -> tuple[float, float]:
        tx, ty = tile_of(lat, lon, z)
        return (tx - x) * TILE, (ty - y) * TILE

    lat0, lon0 = lonlat_of(x, y, z)
    lat1, lon1 = lonlat_of(x + 1, y + 1, z)
    n_top, e_left, _ = geodetic_to_ned(origin, lat0, lon0, 0.0)
    n_bot, e_right, _ = geodetic_to_ned(origin, lat1, lon1, 0.0)
    step = 10.0 if z >= 19 else 50.0 if z >= 18 else 100.0 if z >= 16 else 500.0
    scale = M_PER_DEG * math.cos(math.radians(home[0]))
    for i in range(math.floor(e_left / step), math.ceil(e_right / step) + 1):  # meridians of the grid
        lon = home[1] + i * step / scale
        gx = px(home[0], lon)[0]
        d.line([(gx, 0), (gx, TILE)], fill=(255, 255, 255) if i else (40, 40, 40), width=1)
        d.text((gx + 2, TILE - 12), f"E{i * step:+.0f}", fill=(30, 30, 30))
    for j in range(math.floor(n_bot / step), math.ceil(n_top / step) + 1):  # parallels
        lat = home[0] + j * step / M_PER_DEG
        gy = px(lat, home[1])[1]
        d.line([(0, gy), (TILE, gy)], fill=(255, 255, 255) if j else (40, 40, 40), width=1)
        d.text((2, gy + 2), f"N{j * step:+.0f}", fill=(30, 30, 30))
    hx, hy = px(*home)
    r = max(3.0, 5.0 / (40_075_000 * math.cos(math.radians(home[0])) / 2 ** z / TILE))  # a 10 m pad
    d.rectangle([hx - r, hy - r, hx + r, hy + r], outline=(20, 20, 20), fill=(150, 150, 150))
    d.text((hx + r + 3, hy - 6), "home", fill=(0, 0, 0))
    d.text((3, 3), f"taskflight offline {z}/{x}/{y}", fill=(60, 60, 60))
    out = io.BytesIO()
    img.quantize(48).save(out, "PNG")  # a palette: a few kB a tile
    return out.getvalue()


def tiles_around(home: tuple[float, float], radius_m: float,
                 zooms: Iterable[int]) -> list[tuple[int, int, int]]:
    """Every XYZ tile within ``radius_m`` of ``home`` at each zoom."""
    dlat = radius_m / M_PER_DEG
    dlon = radius_m / (M_PER_DEG * math.cos(math.radians(home[0])))
    out = []
    for z in zooms:
        x0, y0 = tile_of(home[0] + dlat, home[1] - dlon, z)
        x1, y1 = tile_of(home[0] - dlat, home[1] + dlon, z)
        out += [(z, x, y) for x in range(int(x0), int(x1) + 1) for y in range(int(y0), int(y1) + 1)]
    return out


def make_mbtiles(path: Path, home: tuple[float, float], radius_m: float = DEFAULT_RADIUS_M,
                 zooms: Iterable[int] = DEFAULT_ZOOMS) -> Path:
    """Write the MBTiles file ``path`` (replaced) with the tiles around ``home``; returns ``path``."""
    zooms = list(zooms)
    tmp = path.with_suffix(".part")
    tmp.unlink(missing_ok=True)
    db = sqlite3.connect(tmp)
    try:
        db.executescript("CREATE TABLE metadata (name TEXT, value TEXT);"
                         "CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, tile_row INTEGER, "
                         "tile_data BLOB);"
                         "CREATE UNIQUE INDEX tile_index ON tiles (zoom_level, tile_column, tile_row);")
        dlat = radius_m / M_PER_DEG
        dlon = radius_m / (M_PER_DEG * math.cos(math.radians(home[0])))
        meta = {"name": "taskflight offline demo", "format": "png", "type": "baselayer", "version": "1",
                "description": "drawn by taskflight.demo_tiles (not a survey)",
                "attribution": "taskflight offline tiles",
                "minzoom": str(min(zooms)), "maxzoom": str(max(zooms)),
                "bounds": f"{home[1] - dlon},{home[0] - dlat},{home[1] + dlon},{home[0] + dlat}",
                "center": f"{home[1]},{home[0]},{max(zooms) - 1}"}
        db.executemany("INSERT INTO metadata VALUES (?, ?)", meta.items())
        for z, x, y in tiles_around(home, radius_m, zooms):
            db.execute("INSERT INTO tiles VALUES (?, ?, ?, ?)",
                       (z, x, 2 ** z - 1 - y, draw_tile(z, x, y, home)))
        db.commit()
    finally:
        db.close()
    tmp.replace(path)
    return path


def ensure_mbtiles(path: Path, home: tuple[float, float]) -> Path:
    """``path`` if it exists, else made around ``home`` (the first run of ``taskflight up``)."""
    if not path.is_file():
        log.info("drawing the offline map tiles of the demo's area into %s", path)
        make_mbtiles(path, home)
    return path


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 3:
        print("usage: python -m taskflight.demo_tiles OUT.mbtiles LAT LON", file=sys.stderr)
        return 2
    make_mbtiles(Path(args[0]), (float(args[1]), float(args[2])))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
