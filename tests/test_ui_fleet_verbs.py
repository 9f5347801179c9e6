"""The verbs an operator reaches for, and a real map offline, end to end in headless Chromium.

``taskflight up --vehicles 3 --tiles <an MBTiles file made here>`` (tests/conftest.py ``up_rig``, with a
pymavlink ground station per vehicle on its model's MAVLink port); Debian's Chromium logs in as the
operator and: the map draws its base layer from the MBTiles file (the tile images load from the service's
``/tiles/``, which answers each with the file's row in TMS numbering); cancelling one piece of a divided
task asks whether the whole group goes, and "only this piece" leaves the other; a fence drawn on the map
is in every autopilot's fence (read back over MAVLink by the test's own ground stations with
MISSION_REQUEST_LIST, mission type FENCE, and FENCE_ENABLE 1); "Return all home" (button and
confirmation) brings every flying vehicle home and disarmed (its autopilot's HEARTBEAT and position); a
mission file chosen in the page and refused by the vehicle's delegation is shown node by node; the H key
(and a confirmation naming every vehicle) holds a patrolling fleet where it is.
With ``TASKFLIGHT_SCREENSHOTS=docs/img`` the map with tiles and the refusal are saved there.
"""

from __future__ import annotations

import math
import os
import sqlite3
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from harness.ui import missing

if missing():
    pytest.skip(missing() or "", allow_module_level=True)

from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

from harness.fence import VERTEX_INCLUSION, param, read_fence
from harness.ground import GroundRig
from harness.team import HOME
from harness.timing import wait_for
from taskflight.demo_tiles import make_mbtiles, tile_of

pytestmark = [pytest.mark.integration, pytest.mark.timeout(900)]  # the fleet starts slowly on a busy machine

TILES = "test.mbtiles"
SCREENSHOTS = os.environ.get("TASKFLIGHT_SCREENSHOTS")


def up_extra_args(tmp: Path) -> list[str]:
    """``taskflight up``'s map tiles: an MBTiles file drawn here around the fleet's home."""
    make_mbtiles(tmp / TILES, (HOME[0], HOME[1]), radius_m=150.0, zooms=range(17, 20))
    return ["--tiles", str(tmp / TILES), "--ready-timeout", "400"]  # a busy machine starts slowly


def ne(lat: float, lon: float) -> tuple[float, float]:
    return (lat - HOME[0]) * 111_320.0, (lon - HOME[1]) * 111_320.0 * math.cos(math.radians(HOME[0]))


def keep(d: Any, name: str) -> None:
    """A screenshot for the docs (``TASKFLIGHT_SCREENSHOTS=docs/img``)."""
    if SCREENSHOTS:
        Path(SCREENSHOTS).mkdir(parents=True, exist_ok=True)
        d.save_screenshot(str(Path(SCREENSHOTS) / name))


def click_map(d: Any, n: float, e: float) -> None:
    x, y = d.execute_script("return window.taskflight.map.pixelOf(arguments[0], arguments[1])", n, e)
    m = d.find_element(By.ID, "map")
    ActionChains(d).move_to_element_with_offset(m, int(x - m.size["width"] / 2),
                                                int(y - m.size["height"] / 2)).click().perform()


def answer(d: Any, value: str, timeout: float = 10.0) -> str:
    """Press the open dialog's button ``value``; returns the dialog's text."""
    WebDriverWait(d, timeout).until(
        lambda d: d.execute_script("return document.getElementById('dialog').open"), "the dialog")
    text = d.find_element(By.ID, "dialog").text
    d.find_element(By.CSS_SELECTOR, f"#dialog [data-answer='{value}']").click()
    return text


def verb_result(d: Any, verb: str) -> str:
    """The fleet verb's answers line once ``verb`` answered ('' before)."""
    el = d.find_element(By.ID, "verb-result")
    return el.text if el.get_attribute("data-verb") == verb else ""


def test_the_map_draws_tiles_from_an_mbtiles_file(up_rig: GroundRig, page: Any) -> None:
    d = page
    loaded = ("return [...document.querySelectorAll('#map img.leaflet-tile')].filter((i) => i.complete && "
              "i.naturalWidth === 256).map((i) => i.src)")
    srcs = WebDriverWait(d, 30).until(lambda d: (s := d.execute_script(loaded)) and len(s) >= 4 and s,
                                      "tiles drawn on the map")
    assert all("/tiles/" in s and s.startswith(up_rig.ground.url) for s in srcs), srcs
    # the service answers each from the file: XYZ row y is the stored TMS row 2^z - 1 - y
    db = sqlite3.connect(up_rig.tmp / TILES)
    try:
        for src in srcs[:4]:
            z, x, y = (int(v) for v in src.split("/tiles/")[1].removesuffix(".png").split("/"))
            r = httpx.get(src, timeout=10)
            assert r.status_code == 200 and r.headers["content-type"] == "image/png"
            row = db.execute("SELECT tile_data FROM tiles WHERE zoom_level=? AND tile_column=? AND "
                             "tile_row=?", (z, x, 2 ** z - 1 - y)).fetchone()
            assert row is not None and bytes(row[0]) == r.content, f"tile {z}/{x}/{y} is not the file's"
    finally:
        db.close()
    far = tile_of(HOME[0] + 1.0, HOME[1], 19)
    assert httpx.get(f"{up_rig.ground.url}/tiles/19/{int(far[0])}/{int(far[1])}.png").status_code == 404
    # in Web Mercator: the vehicles are drawn at their latitude and longitude
    WebDriverWait(d, 20).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, ".vmarker[data-n]")) == 3)
    keep(d, "map_tiles.png")


def test_cancelling_one_piece_asks_whether_the_group_goes(up_rig: GroundRig, page: Any) -> None:
    d = page
    a, b = (HOME[0] + 25 / 111_320.0, HOME[1] - 0.0003), (HOME[0] + 25 / 111_320.0, HOME[1] + 0.0003)
    with up_rig.ground.http() as c:
        r = c.post("/api/tasks", json={"type": "border_patrol", "points": [[*a, 6.0], [*b, 6.0]],
                                       "altitude": 6.0, "vehicles": 2, "force": True})
        assert r.status_code == 201, r.text
        ids, group = r.json()["ids"], r.json()["group"]
    assert len(ids) == 2
    try:
        row = f"#tasks tr[data-task='{ids[0]}'] button.cancel"
        WebDriverWait(d, 20).until(lambda d: d.find_elements(By.CSS_SELECTOR, row), "the piece listed")
        d.find_element(By.CSS_SELECTOR, row).click()
        text = answer(d, "one")
        assert f"group {group}" in text and str(ids[1]) in text, text
        wait_for(lambda: up_rig.tasks()[ids[0]]["state"] == "cancelled", 20, "the piece cancelled")
        assert up_rig.tasks()[ids[1]]["state"] != "cancelled", "only the piece asked for is cancelled"
    finally:
        with up_rig.ground.http() as c:
            c.delete(f"/api/tasks/{group}")


def test_a_fence_drawn_on_the_map_is_in_every_autopilots_fence(up_rig: GroundRig, page: Any) -> None:
    d = page
    for i, g in enumerate(up_rig.gcs):  # nothing of ours there before
        assert not read_fence(g, i + 1)
    d.find_element(By.CSS_SELECTOR, "[data-fence]").click()
    corners = [(70.0, -70.0), (70.0, 80.0), (-70.0, 80.0), (-70.0, -70.0)]
    for n, e in corners:
        click_map(d, n, e)
    d.find_element(By.ID, "draw-finish").click()
    text = answer(d, "yes")
    assert "3" in text
    wait_for(lambda: verb_result(d, "fence").count("enabled") == 3, up_rig.wall(60),
             lambda: f"every autopilot's answer: {verb_result(d, 'fence')!r}; {up_rig.report()}", poll_s=0.2)
    with up_rig.ground.http() as c:
        sent = c.get("/api/fence").json()["points"]
    assert len(sent) == 4
    for (n, e), p in zip(corners, sent, strict=True):  # the corners clicked, within a pixel or two
        assert math.dist(ne(*p), (n, e)) < 2.0
    for i, g in enumerate(up_rig.gcs):
        items = read_fence(g, i + 1)
        assert [it[0] for it in items] == [VERTEX_INCLUSION] * 4
        assert all(it[1] == 4 for it in items), "param1: the polygon's vertex count"
        for it, p in zip(items, sent, strict=True):
            assert abs(it[2] - p[0]) < 2e-7 and abs(it[3] - p[1]) < 2e-7
        assert param(g, "FENCE_ENABLE", i + 1) == 1.0
        assert int(param(g, "FENCE_TYPE", i + 1)) & 4, "FENCE_TYPE with polygons"


def test_return_all_home_brings_every_vehicle_home_disarmed(up_rig: GroundRig, page: Any) -> None:
    d = page
    homes = [g.home() for g in up_rig.gcs]
    visits = []
    with up_rig.ground.http() as c:  # every vehicle flies away from home first
        for h in homes:
            r = c.post("/api/tasks", json={"type": "visit", "point": [h[0] + 15 / 111_320.0, h[1], 6.0],
                                           "altitude": 6.0})
            assert r.status_code == 201, r.text
            visits += r.json()["ids"]
    try:
        rtl_all_and_check(up_rig, d, homes)
    finally:
        with up_rig.ground.http() as c:  # no visit left for the next test's vehicles
            for tid in visits:
                c.delete(f"/api/tasks/{tid}")


def rtl_all_and_check(up_rig: GroundRig, d: Any, homes: list[Any]) -> None:
    """Once every vehicle flies away from home: "Return all home", confirmed, and each home, disarmed."""

    def away(i: int) -> bool:
        p = up_rig.position(i)
        return p is not None and p[2] > 2.0 and math.dist(ne(p[0], p[1]), ne(*homes[i][:2])) > 6.0

    wait_for(lambda: all(away(i) for i in range(up_rig.n)), up_rig.wall(240),
             lambda: f"every vehicle away from home: {up_rig.report()}")
    assert all(g.armed() for g in up_rig.gcs)
    with up_rig.ground.http() as c:
        since = c.get("/api/events").json()["last_id"]
    d.find_element(By.CSS_SELECTOR, "[data-verb='rtl_all']").click()
    text = answer(d, "yes")
    assert all(f"({i + 1})" in text for i in range(up_rig.n)), text  # every target named
    result = WebDriverWait(d, 30).until(lambda d: verb_result(d, "rtl_all"), "every vehicle's answer")
    assert result.count(": ok") == up_rig.n, result

    def home_and_disarmed(i: int) -> bool:
        p = up_rig.position(i)
        return (p is not None and math.dist(ne(p[0], p[1]), ne(*homes[i][:2])) < 2.0 and p[2] < 0.5
                and not up_rig.gcs[i].armed())

    wait_for(lambda: all(home_and_disarmed(i) for i in range(up_rig.n)), up_rig.wall(300),
             lambda: f"every vehicle home and disarmed (MAVLink): {up_rig.report()}")
    with up_rig.ground.http() as c:  # the operator's own return is history, never a failsafe alert
        kinds = [(e["kind"], e["message"]) for e in c.get(f"/api/events?since={since}").json()["events"]]
    assert not [k for k in kinds if k[0] == "failsafe"], kinds


MISSION = """mission: too-far
description: a fly-to 3 km north, outside every fence
tree:
  type: S
  id: root
  children:
    - {type: take-off, id: up}
    - {type: fly-to, id: far, params: {position: [%f, %f, 10.0], speed: standard}}
    - {type: land, id: down}
"""


def test_a_mission_refused_is_shown_node_by_node(up_rig: GroundRig, page: Any, tmp_path: Path) -> None:
    d = page
    assert up_rig.vehicles()[1].get("team_state") != "taken"
    path = tmp_path / "too_far.yaml"
    path.write_text(MISSION % (HOME[0] + 3000 / 111_320.0, HOME[1]))
    WebDriverWait(d, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#mu-vehicle option[value='1']"))
    d.find_element(By.CSS_SELECTOR, "#mu-vehicle option[value='1']").click()
    bundled = [o.get_attribute("value") for o in d.find_elements(By.CSS_SELECTOR, "#mu-bundled option")]
    assert "scan_and_search_outdoor.yaml" in bundled  # the service's bundled missions are offered too
    d.find_element(By.ID, "mu-file").send_keys(str(path))
    d.find_element(By.ID, "mu-go").click()
    text = answer(d, "yes")
    assert "too-far" in text and "vehicle 1" in text
    WebDriverWait(d, 30).until(lambda d: d.find_element(By.ID, "mu-result").get_attribute("data-state")
                               in ("rejected", "accepted", "error"))
    out = d.find_element(By.ID, "mu-result")
    assert out.get_attribute("data-state") == "rejected", out.text
    far = out.find_element(By.CSS_SELECTOR, "li.node[data-node='far']")
    assert "refused" in far.get_attribute("class")
    assert "outside" in far.find_element(By.CSS_SELECTOR, "ul.reasons").text
    for ok in ("up", "down"):
        node = out.find_element(By.CSS_SELECTOR, f"li.node[data-node='{ok}']")
        assert "refused" not in (node.get_attribute("class") or "")
    keep(d, "mission_refused.png")
    # the refused mission left the vehicle on its team task: it is never "taken" (sampled for 2 s, the
    # ground's snapshots come at 5 Hz)
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        assert up_rig.vehicles()[1].get("team_state") != "taken"
        time.sleep(0.1)


def test_hold_all_on_the_h_key_stops_every_vehicle_where_it_is(up_rig: GroundRig, page: Any) -> None:
    """The H key asks (every vehicle named), then every vehicle's mission is paused with the hover routine:
    each patrolling vehicle comes to rest and stays where it stopped, its mission ``paused``."""
    d = page
    a, b = (HOME[0] - 50 / 111_320.0, HOME[1] - 0.0004), (HOME[0] + 50 / 111_320.0, HOME[1] + 0.0004)
    with up_rig.ground.http() as c:  # a border patrolled back and forth by all three (inside the fence)
        r = c.post("/api/tasks", json={"type": "border_patrol", "points": [[*a, 6.0], [*b, 6.0]],
                                       "altitude": 6.0, "vehicles": up_rig.n, "force": True})
        assert r.status_code == 201, r.text
        group = r.json()["group"]

    def speed(i: int) -> float:
        v = up_rig.velocity(i)
        return math.hypot(v[0], v[1]) if v is not None else 0.0

    def patrolling(vid: int, v: dict[str, Any]) -> bool:
        p = up_rig.position(vid - 1)
        m = v.get("mission") or {}  # on the patrol's legs (a take-off node cannot be paused)
        return m.get("state") == "executing" and "waypoint" in str(m.get("progress")) and p is not None \
            and p[2] > 2.0

    try:
        wait_for(lambda: all(patrolling(vid, v) for vid, v in up_rig.vehicles().items())
                 and any(speed(i) > 0.5 for i in range(up_rig.n)), up_rig.wall(240),
                 lambda: f"every vehicle patrolling: {up_rig.report()}")
        d.find_element(By.TAG_NAME, "header").click()  # the key goes to the page, not to a text box
        ActionChains(d).send_keys("h").perform()
        text = answer(d, "yes")
        assert "Hold all" in text and all(f"({i + 1})" in text for i in range(up_rig.n)), text
        result = WebDriverWait(d, 30).until(lambda d: verb_result(d, "hold_all"), "every vehicle's answer")
        assert result.count(": ok") == up_rig.n, result
        wait_for(lambda: all(speed(i) < 0.3 for i in range(up_rig.n)), up_rig.wall(20),
                 lambda: f"every vehicle at rest: {[speed(i) for i in range(up_rig.n)]}")
        stopped = [up_rig.position(i) for i in range(up_rig.n)]
        deadline = time.monotonic() + up_rig.wall(10)  # it stays there: sampled over 10 s of its time
        while time.monotonic() < deadline:
            for i, p0 in enumerate(stopped):
                p = up_rig.position(i)
                assert p is not None and p0 is not None
                assert math.dist(ne(p[0], p[1]), ne(p0[0], p0[1])) < 1.0, f"vehicle {i + 1} moved on"
            time.sleep(0.2)
        states = {vid: (v.get("mission") or {}).get("state") for vid, v in up_rig.vehicles().items()}
        assert set(states.values()) == {"paused"}, states
    finally:
        with up_rig.ground.http() as c:
            c.delete(f"/api/tasks/{group}")
