"""The operator's web UI end to end in headless Chromium.

``taskflight up --vehicles 3`` (3 models in one process, 3 companion processes on one team link and
``taskflight ground``; tests/up_support.UpRig, with a pymavlink ground station per vehicle);
Debian's Chromium driven by selenium logs in through the page and works it as an operator: three vehicles
move on the map after visits clicked on it (allocated and flown: the MAVLink tracks reach the points); a
patrol drawn on the map is cancelled from the task list; a vehicle flying a scan is broken into, flown
with the keyboard joystick (it moves north on the MAVLink track), resumed, and ``enough`` ends the scan;
an observer's buttons are disabled and its API calls refused. A screenshot of each step is saved; the
performance log of every page load shows no request to any host but the service.
"""

from __future__ import annotations

import math
import time
from typing import Any

import pytest
import yaml

from harness.ui import Shots, browser, foreign, login, missing, requested_urls

if missing():
    pytest.skip(missing() or "", allow_module_level=True)

from selenium.common.exceptions import StaleElementReferenceException
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

from harness import ROOT
from harness.ground import OBSERVER, OPERATOR, GroundRig
from harness.team import HOME
from harness.timing import wait_for

pytestmark = pytest.mark.integration

SCAN_AND_SEARCH = yaml.safe_load((ROOT / "mission_specs" / "scan_and_search.yaml").read_text())
SCAN_AND_SEARCH["tree"]["children"][2]["params"]["position"][2] = 5.0  # the outdoor platform's 3 m floor
URLS: list[str] = []  # every request of every page in this module


def local(p: Any) -> tuple[float, float]:
    """(north, east) metres of a (lat, lon, ...) point from the fleet's home."""
    return ((p[0] - HOME[0]) * 111_320.0, (p[1] - HOME[1]) * 111_320.0 * math.cos(math.radians(HOME[0])))


def markers(d: Any) -> dict[int, tuple[float, float]]:
    """Each vehicle's (north, east) on the map, as drawn (the marker's data attributes)."""
    out = {}
    for el in d.find_elements(By.CSS_SELECTOR, ".vmarker[data-n]"):
        out[int(el.get_attribute("data-vehicle"))] = (float(el.get_attribute("data-n")),
                                                      float(el.get_attribute("data-e")))
    return out


def click_map(d: Any, n: float, e: float) -> None:
    """Click the map at the point n m north, e m east of the UI's home."""
    x, y = d.execute_script("return window.taskflight.map.pixelOf(arguments[0], arguments[1])", n, e)
    m = d.find_element(By.ID, "map")
    ActionChains(d).move_to_element_with_offset(m, int(x - m.size["width"] / 2),
                                                int(y - m.size["height"] / 2)).click().perform()


def task_state(d: Any, tid: int) -> str:
    rows = d.find_elements(By.CSS_SELECTOR, f"#tasks tr[data-task='{tid}'] td.state")
    return rows[0].text if rows else ""


def task_ids(d: Any) -> set[int]:
    return {int(r.get_attribute("data-task")) for r in d.find_elements(By.CSS_SELECTOR, "#tasks tbody tr")}


def test_three_vehicles_move_to_visits_clicked_on_the_map(up_rig: GroundRig, page: Any, shots: Shots) -> None:
    d = page
    WebDriverWait(d, 30).until(lambda d: len(markers(d)) == 3)
    # taskflight up gives the ground service the platform's envelope: the map draws it
    WebDriverWait(d, 10).until(lambda d: d.find_elements(By.CSS_SELECTOR, "path.fence"), "the fence drawn")
    shots(d, "1_fleet")
    start = markers(d)
    before = task_ids(d)
    t0 = time.monotonic()
    for k, (n, e) in enumerate(sorted(start.values())):  # a visit 8 m north of each vehicle
        d.find_element(By.CSS_SELECTOR, "[data-draw='visit']").click()
        click_map(d, n + 8.0, e)
        want = len(before) + k + 1
        WebDriverWait(d, 20).until(lambda d, w=want: len(task_ids(d)) >= w, f"visit {k + 1} in the task list")
    new = sorted(task_ids(d) - before)
    assert len(new) == 3
    points = {t: up_rig.tasks()[t]["points"][0] for t in new}
    WebDriverWait(d, up_rig.wall(60)).until(
        lambda d: all(task_state(d, t) in ("assigned", "active", "done") for t in new), "visits allocated")
    shots(d, "2_visits_allocated")
    WebDriverWait(d, up_rig.wall(120)).until(
        lambda d: all(math.dist(markers(d)[v], start[v]) > 3.0 for v in start), "all three vehicles moving")
    shots(d, "3_three_moving")
    WebDriverWait(d, up_rig.wall(300)).until(lambda d: all(task_state(d, t) == "done" for t in new),
                                             "the visits flown")
    shots(d, "4_visits_flown")
    for t, p in points.items():  # flown: a MAVLink track (not the service's view) reached each point
        goal = local(p)
        assert any(math.dist(local(s[1:]),
                             goal) < 2.5 for i in range(up_rig.n) for s in list(up_rig.tracks[i])
                   if s[0] >= t0), f"nobody reached task {t}'s point (MAVLink)"


def test_a_patrol_drawn_on_the_map_is_cancelled_from_the_task_list(up_rig: GroundRig, page: Any,
                                                                   shots: Shots) -> None:
    d = page
    before = task_ids(d)
    d.find_element(By.CSS_SELECTOR, "[data-draw='patrol_line']").click()
    click_map(d, -15.0, -10.0)
    click_map(d, -15.0, 10.0)
    d.find_element(By.ID, "draw-finish").click()
    WebDriverWait(d, 20).until(lambda d: task_ids(d) - before, "the patrol in the task list")
    tid = max(task_ids(d) - before)
    assert up_rig.tasks()[tid]["kind"] == "patrol_line"
    WebDriverWait(d, up_rig.wall(60)).until(lambda d: task_state(d, tid) in ("assigned", "active"),
                                            "allocated")
    shots(d, "5_patrol")
    d.find_element(By.CSS_SELECTOR, f"#tasks tr[data-task='{tid}'] button.cancel").click()
    WebDriverWait(d, 20).until(lambda d: task_state(d, tid) == "cancelled", "the patrol cancelled")
    assert up_rig.tasks()[tid]["state"] == "cancelled"
    shots(d, "6_cancelled")


def test_a_border_for_more_vehicles_than_are_free_takes_the_offered_smaller_n(up_rig: GroundRig, page: Any,
                                                                             shots: Shots) -> None:
    """Seed 003 Sec. II: a border patrol asked of more vehicles than are free; the service offers a smaller N
    in a dialog, the operator accepts it, the border is divided into that many pieces (then cancelled)."""
    d = page
    before = task_ids(d)
    n_box = d.find_element(By.ID, "task-n")
    n_box.clear()
    n_box.send_keys("9")
    try:
        d.find_element(By.CSS_SELECTOR, "[data-draw='border_patrol']").click()
        for n, e in ((-30.0, -20.0), (-30.0, 0.0), (-30.0, 20.0)):
            click_map(d, n, e)
        d.find_element(By.ID, "draw-finish").click()
        wait = WebDriverWait(d, 20)
        wait.until(lambda d: d.find_element(By.ID, "dialog").get_attribute("open") is not None,
                   "the dialog offering a smaller N")
        offer = int(d.find_element(By.CSS_SELECTOR, "#dialog-body .offer").text)
        assert 1 <= offer < 9 and "9 vehicles asked for" in d.find_element(By.ID, "dialog-body").text
        shots(d, "6b_smaller_n_offered")
        d.find_element(By.CSS_SELECTOR, "#dialog-buttons button[data-answer='accept']").click()
        wait.until(lambda d: len(task_ids(d) - before) == offer, f"{offer} border pieces listed")
    finally:
        n_box.clear()
        n_box.send_keys("2")
    pieces = {t: up_rig.tasks()[t] for t in task_ids(d) - before}
    assert {t["kind"] for t in pieces.values()} == {"border_piece"}
    assert len({t["group"] for t in pieces.values()}) == 1
    d.find_element(By.CSS_SELECTOR, f"#tasks tr[data-task='{min(pieces)}'] button.cancel").click()
    if len(pieces) > 1:  # one piece of a divided task: the page asks whether the whole group goes
        WebDriverWait(d, 20).until(
            lambda d: d.find_element(By.ID, "dialog").get_attribute("open") is not None, "the group asked")
        d.find_element(By.CSS_SELECTOR, "#dialog-buttons button[data-answer='group']").click()  # all
    WebDriverWait(d, 20).until(lambda d: all(task_state(d, t) == "cancelled" for t in pieces),
                               "the border cancelled")


def test_break_in_with_the_keyboard_joystick_resume_and_enough_ends_the_scan(up_rig: GroundRig, page: Any,
                                                                            shots: Shots) -> None:
    d, i, vid = page, 2, 3
    with up_rig.ground.http() as c:
        if up_rig.vehicles()[vid]["armed"]:  # a mission starts with a take-off: from the ground
            assert c.post(f"/api/vehicles/{vid}/land").status_code == 200
            wait_for(lambda: up_rig.vehicles()[vid]["armed"] is False, up_rig.wall(90), "vehicle 3 landed")
        r = c.post(f"/api/vehicles/{vid}/mission", json={**SCAN_AND_SEARCH, "start": True})
        assert r.status_code == 200, r.text

    def mission() -> dict[str, Any]:
        return up_rig.vehicles()[vid]["mission"]

    wait_for(lambda: mission()["node"] == "scan" and (mission()["progress"] or "").startswith("waypoint"),
             up_rig.wall(120), "the scan under way")
    d.find_element(By.CSS_SELECTOR, f"#fleet tr[data-vehicle='{vid}']").click()
    wait = WebDriverWait(d, 30)
    wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, ".tree li[data-node='scan']"), "the mission tree")
    shots(d, "7_mission_tree")
    d.find_element(By.CSS_SELECTOR, "[data-verb='pause']").click()
    wait.until(lambda d: d.find_element(By.CSS_SELECTOR, ".joystick").is_displayed(), "the joystick shown")
    wait.until(lambda d: mission()["state"] == "paused", "paused (the service's view)")
    start = up_rig.position(i)

    def moved() -> float:
        return local(up_rig.position(i))[0] - local(start)[0]

    # north at 2 m/s while W is held: until 8 m are flown (judged by MAVLink, not by the wall clock: a loaded
    # machine runs the simulation slower than its speed-up), at most 24 s of autopilot time
    ActionChains(d).key_down("w").perform()
    try:
        wait_for(lambda: moved() > 8.0, up_rig.wall(24.0), "moved north under the keyboard joystick",
                 poll_s=0.1)
        shots(d, "8_joystick")
    finally:
        ActionChains(d).key_up("w").perform()
    assert d.execute_script("return window.taskflight.joystick.sent") > 15  # 15 Hz while held
    d.find_element(By.CSS_SELECTOR, "[data-verb='resume']").click()
    wait_for(lambda: mission()["state"] == "executing", 20, "resumed")
    wait.until(lambda d: not d.find_element(By.CSS_SELECTOR, ".joystick").is_displayed(), "the joystick gone")
    d.find_element(By.CSS_SELECTOR, "[data-verb='enough']").click()
    wait_for(lambda: mission()["node"] in ("fly-to", "land") or mission()["state"] == "succeeded",
             up_rig.wall(60), "the mission goes on after enough")
    WebDriverWait(d, 20, ignored_exceptions=(StaleElementReferenceException,)).until(  # the tree redrawn
        lambda d: d.find_element(By.CSS_SELECTOR,
                                 ".tree li[data-node='scan'] > span.state").text == "succeeded",
        "the scan ended")
    shots(d, "9_enough")


def test_an_observer_sees_everything_and_commands_nothing(up_rig: GroundRig, shots: Shots) -> None:
    d = browser()
    try:
        login(d, up_rig.ground.url, OBSERVER)
        WebDriverWait(d, 30).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#fleet tbody tr")) == 3)
        d.find_element(By.CSS_SELECTOR, "#fleet tr[data-vehicle='1']").click()
        WebDriverWait(d, 20).until(lambda d: d.find_elements(By.CSS_SELECTOR, "[data-verb='pause']"))
        buttons = d.find_elements(By.CSS_SELECTOR, "[data-cmd]")
        assert len(buttons) >= 12
        for b in buttons:
            assert not b.is_enabled() and "observer" in b.get_attribute("title"), b.get_attribute("outerHTML")
        shots(d, "10_observer")
        statuses = d.execute_async_script("""
            const done = arguments[arguments.length - 1];
            const c = window.taskflight.call;
            Promise.all([c("POST", "/api/tasks", {type: "visit", point: [-35.36, 149.16]}),
                         c("POST", "/api/vehicles/1/pause"), c("DELETE", "/api/tasks/1"),
                         c("GET", "/api/vehicles")]).then((rs) => done(rs.map((r) => r.status)));""")
        assert statuses == [403, 403, 403, 200]
    finally:
        URLS.extend(requested_urls(d))
        d.quit()


def test_the_network_log_shows_only_the_service(up_rig: GroundRig) -> None:
    d = browser()
    try:
        login(d, up_rig.ground.url, OPERATOR)
        WebDriverWait(d, 30).until(lambda d: len(markers(d)) == 3)
    finally:
        URLS.extend(requested_urls(d))
        d.quit()
    assert any(u.endswith("/static/vendor/leaflet/leaflet.js") for u in URLS)
    assert any("/api/ws" in u for u in URLS)
    assert foreign(URLS, up_rig.ground.url) == [], "requests left the service's host"
