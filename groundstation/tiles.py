"""The map's raster tiles, offline: an MBTiles file served at ``/tiles/{z}/{x}/{y}.png``, or a tile URL
template handed to the page (``taskflight ground --tiles FILE.mbtiles|URL-template``).

MBTiles 1.3 (https://github.com/mapbox/mbtiles-spec): an SQLite file with a ``tiles(zoom_level,
tile_column, tile_row, tile_data)`` table and a ``metadata(name, value)`` table. Rows are numbered as TMS
does, from the south: the XYZ (slippy map, Web Mercator EPSG:3857) row ``y`` of zoom ``z`` is the stored
``tile_row`` ``2**z - 1 - y``. The file is opened read-only; nothing is downloaded at run time.
"""

from __future__ import annotations

import sqlite3
import threading
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

MIME = {"png": "image/png", "jpg": "image/jpeg", "jpeg": "image/jpeg", "webp": "image/webp"}
LOCAL_URL = "/tiles/{z}/{x}/{y}.png"


class MBTiles:
    """A read-only MBTiles file (see module docstring); thread-safe."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise ValueError(f"--tiles {path}: no such file")
        try:
            self._db = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True, check_same_thread=False)
            self.metadata = dict(self._db.execute("SELECT name, value FROM metadata").fetchall())
            zooms = self._db.execute("SELECT MIN(zoom_level), MAX(zoom_level) FROM tiles").fetchone()
        except sqlite3.DatabaseError as exc:
            raise ValueError(f"--tiles {path}: not an MBTiles file: {exc}") from None
        if zooms[0] is None:
            raise ValueError(f"--tiles {path}: the file holds no tile")
        self._lock = threading.Lock()
        self.minzoom = int(self.metadata.get("minzoom", zooms[0]))
        self.maxzoom = int(self.metadata.get("maxzoom", zooms[1]))
        self.mime = MIME.get(str(self.metadata.get("format", "png")).lower(), "image/png")

    def tile(self, z: int, x: int, y: int) -> bytes | None:
        """The tile at XYZ ``z/x/y`` (None when the file has none there)."""
        if not (0 <= z <= 30 and 0 <= x < 2 ** z and 0 <= y < 2 ** z):
            return None
        with self._lock:
            row = self._db.execute("SELECT tile_data FROM tiles WHERE zoom_level=? AND tile_column=? AND "
                                   "tile_row=?", (z, x, 2 ** z - 1 - y)).fetchone()
        return bytes(row[0]) if row else None

    def info(self) -> dict[str, Any]:
        bounds = self.metadata.get("bounds")
        return {"url": LOCAL_URL, "minzoom": self.minzoom, "maxzoom": self.maxzoom,
                "bounds": [float(v) for v in bounds.split(",")] if bounds else None,
                "attribution": self.metadata.get("attribution") or self.metadata.get("name") or ""}

    def close(self) -> None:
        self._db.close()


class TileSource:
    """What ``--tiles`` names: an MBTiles file served here, or a URL template the page fetches itself."""

    def __init__(self, spec: str) -> None:
        self.spec = spec
        self.mbtiles: MBTiles | None = None
        if "{z}" in spec and "{x}" in spec and "{y}" in spec:
            if not spec.startswith(("http://", "https://", "/")):
                raise ValueError(f"--tiles {spec!r}: a URL template starts with http://, https:// or /")
            self.origin()  # a bad host is refused at start
        else:
            self.mbtiles = MBTiles(spec)

    def info(self) -> dict[str, Any]:
        """``GET /api/map``'s ``tiles``: the URL template the page draws from, its zooms and bounds."""
        if self.mbtiles is not None:
            return self.mbtiles.info()
        return {"url": self.spec, "minzoom": 0, "maxzoom": 19, "bounds": None, "attribution": ""}

    def origin(self) -> str | None:
        """The other host a URL template fetches from (``https://tile.example.org``), for the page's
        Content-Security-Policy; None when the tiles are this service's own."""
        if self.mbtiles is not None or self.spec.startswith("/"):
            return None
        parts = urlsplit(self.spec)
        host = parts.netloc
        if host.startswith("{s}."):
            host = "*." + host[4:]  # Leaflet's subdomains: a CSP host wildcard
        if not host or "{" in host or any(c in host for c in " ;,'\""):
            raise ValueError(f"--tiles {self.spec!r}: the host must be written out (only a leading {{s}}. "
                             "placeholder)")
        return f"{parts.scheme}://{host}"

    def close(self) -> None:
        if self.mbtiles is not None:
            self.mbtiles.close()
