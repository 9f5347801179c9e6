"""The web UI's flat earth (``groundstation/static/js/geo.js``) is the Python one
(:mod:`taskflight_common.geo`).

The browser cannot import Python, so the projection is written twice; this test runs the JavaScript
module with Node.js and compares both ways of the projection with ArduPilot's at points around the
bundled home and far from it.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from taskflight_common.geo import geodetic_to_ned, ned_to_geodetic

pytestmark = pytest.mark.integration

GEO_JS = Path(__file__).resolve().parents[1] / "groundstation" / "static" / "js" / "geo.js"
HOMES = [(-35.363261, 149.165230), (0.0, 0.0), (64.1, -21.9), (89.9, 10.0)]
OFFSETS = [(0.0, 0.0), (120.0, -75.0), (-2500.0, 4000.0)]


def _js(points: list[tuple[float, float, float, float]], tmp_path: Path) -> list[dict[str, list[float]]]:
    node = shutil.which("node")
    if node is None:
        pytest.skip("Node.js is not installed: the UI's projection cannot be run outside a browser")
    module = tmp_path / "geo.mjs"
    module.write_text(GEO_JS.read_text(encoding="utf-8"), encoding="utf-8")
    script = (f"import {{ setHome, toLocal, toGeo }} from {json.dumps(module.as_uri())};\n"
              f"const out = {json.dumps(points)}.map(([hl, ho, n, e]) => {{ setHome(hl, ho);\n"
              "  const g = toGeo(n, e); return { geo: g, back: toLocal(g[0], g[1]) }; });\n"
              "console.log(JSON.stringify(out));\n")
    done = subprocess.run([node, "--input-type=module", "-e", script], capture_output=True, text=True,
                          timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_the_ui_projects_as_the_python_geodesy_does(tmp_path: Path) -> None:
    points = [(lat, lon, n, e) for lat, lon in HOMES for n, e in OFFSETS]
    results = _js(points, tmp_path)
    for (lat, lon, n, e), got in zip(points, results, strict=True):
        want_lat, want_lon, _ = ned_to_geodetic((lat, lon, 0.0), n, e, 0.0)
        assert got["geo"][0] == pytest.approx(want_lat, abs=1e-9), (lat, lon, n, e)
        assert got["geo"][1] == pytest.approx(want_lon, abs=1e-9), (lat, lon, n, e)
        back_n, back_e, _ = geodetic_to_ned((lat, lon, 0.0), *got["geo"], 0.0)
        assert got["back"] == pytest.approx([back_n, back_e], abs=1e-6)
        assert got["back"] == pytest.approx([n, e], abs=1e-6)
