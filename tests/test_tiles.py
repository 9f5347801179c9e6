"""The map's offline tiles: an MBTiles file drawn by ``taskflight.demo_tiles`` and read back by
``groundstation.tiles`` at XYZ numbering (MBTiles rows are TMS: row = 2^z - 1 - y), and ``--tiles``
refusing what is not a tile source."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from groundstation.tiles import LOCAL_URL, MBTiles, TileSource
from taskflight.demo_tiles import lonlat_of, make_mbtiles, tile_of

HOME = (-35.363261, 149.165230)


def test_a_drawn_tile_set_is_read_back_at_xyz_numbering(tmp_path: Path) -> None:
    path = make_mbtiles(tmp_path / "t.mbtiles", HOME, radius_m=60.0, zooms=[17, 18])
    m = MBTiles(path)
    try:
        x, y = (int(v) for v in tile_of(*HOME, 18))
        png = m.tile(18, x, y)
        assert png is not None and png.startswith(b"\x89PNG")
        db = sqlite3.connect(path)
        row = db.execute("SELECT tile_data FROM tiles WHERE zoom_level=18 AND tile_column=? AND tile_row=?",
                         (x, 2 ** 18 - 1 - y)).fetchone()
        db.close()
        assert bytes(row[0]) == png
        assert m.tile(18, x, 2 ** 18 - 1 - y) is None  # the unflipped row is another place: not in the file
        assert m.tile(18, x, -1) is None and m.tile(40, 0, 0) is None
        info = m.info()
        assert info["url"] == LOCAL_URL and (info["minzoom"], info["maxzoom"]) == (17, 18)
        west, south, east, north = info["bounds"]
        assert south < HOME[0] < north and west < HOME[1] < east
    finally:
        m.close()


def test_tile_numbering_round_trips() -> None:
    x, y = tile_of(*HOME, 18)
    assert lonlat_of(x, y, 18) == pytest.approx(HOME, abs=1e-9)


def test_tiles_option_refuses_what_is_not_a_tile_source(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no such file"):
        TileSource(str(tmp_path / "absent.mbtiles"))
    (tmp_path / "bad.mbtiles").write_bytes(b"not sqlite at all" * 100)
    with pytest.raises(ValueError, match="not an MBTiles file"):
        TileSource(str(tmp_path / "bad.mbtiles"))
    with pytest.raises(ValueError, match="URL template"):
        TileSource("ftp://host/{z}/{x}/{y}.png")
    assert TileSource("https://tiles.example/{z}/{x}/{y}.png").info()["url"].startswith("https://")


def test_a_tile_url_template_widens_only_the_pages_image_policy() -> None:
    """The page's Content-Security-Policy admits a URL template's host for images, and nothing else of it."""
    from groundstation.app import CSP, security_headers

    assert security_headers(None)[0][1].decode() == CSP
    assert TileSource("/tiles/{z}/{x}/{y}.png").origin() is None
    src = TileSource("https://{s}.tile.example.org/osm/{z}/{x}/{y}.png")
    assert src.origin() == "https://*.tile.example.org"
    csp = dict(security_headers(src))[b"content-security-policy"].decode()
    rules = dict(r.strip().split(" ", 1) for r in csp.split(";"))
    assert rules["img-src"] == "'self' data: https://*.tile.example.org"
    assert rules["script-src"] == "'self'" and rules["connect-src"] == "'self'"
    with pytest.raises(ValueError, match="host"):
        TileSource("https://{s}x.example.org/{z}/{x}/{y}.png")
    with pytest.raises(ValueError, match="host"):
        TileSource("https://a.example.org;script-src*/{z}/{x}/{y}.png")
