"""The operator's station is safe to fly with: guarded parameter writes, nothing from the data runs as code,
a layout for a tablet. ``taskflight up --vehicles 3`` (the up_rig fixture) with a pymavlink ground station
per vehicle, Debian's headless Chromium at 1024 x 768 (a field tablet) driven by selenium.

* Parameter writes: the ground service refuses a name outside the tables of tunable parameters, an empty,
  non-numeric or out-of-range value, and more than a 50 % change in flight without ``force`` (400 naming the
  field; the autopilot's value, read by pymavlink, unchanged); the audit log keeps the old and the new value.
  In the page, "set" with an empty box sends nothing (no 0 written); a number asks for confirmation in a
  dialog showing the old and the new value, and once confirmed it is the autopilot's value.
* A vehicle named ``<img src=x onerror=window.__xss=1>`` is shown as text in the fleet list, on the map,
  in the vehicle panel and in a confirmation dialog; no element is made of it and its handler never runs.
  Every answer carries a Content-Security-Policy allowing only the service's own scripts and styles, and the
  page runs under it without a single violation.
* At 1024 x 768 the map and the side panel fit without a horizontal scroll; "?" lists the shortcuts, "M"
  hides and shows the panel.

Screenshots: under the test's temporary folder, and into ``$TASKFLIGHT_SCREENSHOTS`` (e.g. docs/img) when set.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from harness.ui import Shots, browser, login, missing

if missing():
    pytest.skip(missing() or "", allow_module_level=True)

from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import WebDriverWait

from harness.ground import GroundRig
from harness.timing import wait_for

pytestmark = pytest.mark.integration

XSS = "<img src=x onerror=window.__xss=1>"
GAIN = "ATC_RAT_RLL_P"
WIDTH, HEIGHT = 1024, 768


def doc_shot(d: Any, shots: Shots, name: str) -> None:
    """A screenshot of the step; also ``$TASKFLIGHT_SCREENSHOTS/<name>.png`` when that is set (docs/img)."""
    shots(d, name)
    out = os.environ.get("TASKFLIGHT_SCREENSHOTS")
    if out:
        Path(out).mkdir(parents=True, exist_ok=True)
        d.save_screenshot(str(Path(out) / f"{name}.png"))


@pytest.fixture(scope="module")
def flying(up_rig: GroundRig) -> int:
    """The id of a vehicle in the air (a visit 8 m north of vehicle 1 flown; idle, it hovers there)."""
    lat, lon, _ = up_rig.position(0) or (0.0, 0.0, 0.0)
    with up_rig.ground.http() as c:
        r = c.post("/api/tasks", json={"type": "visit", "point": [lat + 8.0 / 111_320.0, lon, 6.0],
                                       "altitude": 6.0})
        assert r.status_code == 201, r.text

    def airborne() -> int | None:
        for i, g in enumerate(up_rig.gcs):
            p = up_rig.position(i)
            if g.armed() and p is not None and p[2] > 2.0:
                return i + 1
        return None
    return int(wait_for(airborne, up_rig.wall(90), "a vehicle in the air"))


@pytest.fixture(scope="module")
def tablet(up_rig: GroundRig) -> Iterator[Any]:
    d = browser(WIDTH, HEIGHT)
    try:  # the page's viewport is the tablet's screen (the window's size would include the browser's frame)
        d.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                          {"width": WIDTH, "height": HEIGHT, "deviceScaleFactor": 1, "mobile": False})
        login(d, up_rig.ground.url, "op-token-for-tests")
        WebDriverWait(d, 30).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#fleet tbody tr")) == 3)
        yield d
    finally:
        d.quit()


def observed(rig: GroundRig, i: int, name: str) -> float:
    """Vehicle ``i``'s value of ``name``, asked of its autopilot by a pymavlink ground station."""
    return rig.gcs[i].param(name)


def param_audit(rig: GroundRig) -> list[dict[str, Any]]:
    with rig.ground.http() as c:
        entries = c.get("/api/audit", params={"limit": 5000}).json()["entries"]
    return [e for e in entries if e["action"] == "param"]


def pick(d: Any, vid: int) -> None:
    d.find_element(By.CSS_SELECTOR, f"#fleet tr[data-vehicle='{vid}'] td:nth-child(3)").click()
    WebDriverWait(d, 20).until(lambda d: d.find_elements(By.CSS_SELECTOR, "#vehicle .params"))


def test_the_service_refuses_unknown_names_bad_values_and_big_changes_in_flight(up_rig: GroundRig,
                                                                                 flying: int) -> None:
    i, vid = flying - 1, flying
    before = observed(up_rig, i, GAIN)
    url = f"/api/vehicles/{vid}/params"
    with up_rig.ground.http() as c:
        got = c.get(f"{url}/{GAIN}").json()
        assert got["value"] == pytest.approx(before) and got["autopilot"] == "model"  # the model's own table
        assert (got["min"], got["max"], got["units"]) == (0.0, 200.0, "1/s")
        for name, body, field in (("NO_SUCH_PARAM", {"value": 1.0}, "name"),
                                  (GAIN, {"value": ""}, "value"), (GAIN, {"value": "abc"}, "value"),
                                  (GAIN, {"value": None}, "value"), (GAIN, {"value": 1e6}, "value"),
                                  (GAIN, {"value": -1.0}, "value"), (GAIN, {"value": before * 1.6}, "force"),
                                  (GAIN, {"value": before * 0.4}, "force")):
            r = c.put(f"{url}/{name}", json=body)
            assert r.status_code == 400, (body, r.text)
            assert r.json()["error"].startswith(f"{field}: "), (body, r.text)
        assert observed(up_rig, i, GAIN) == pytest.approx(before), "a refused write reached the autopilot"
        # forced (the operator's override of the in-flight bound), on a harmless parameter, then back
        radius = c.get(f"{url}/WPNAV_RADIUS").json()["value"]
        r = c.put(f"{url}/WPNAV_RADIUS", json={"value": radius * 2})
        assert r.status_code == 400 and r.json()["error"].startswith("force: "), r.text
        r = c.put(f"{url}/WPNAV_RADIUS", json={"value": radius * 2, "force": True})
        assert r.status_code == 200, r.text
        assert r.json()["old"] == pytest.approx(radius) and observed(up_rig, i, "WPNAV_RADIUS") == radius * 2
        assert c.put(f"{url}/WPNAV_RADIUS", json={"value": radius}).status_code == 200  # -50 %: allowed
        entries = [e for e in c.get("/api/audit").json()["entries"] if e["action"] == "param"]
    forced = [e for e in entries if e["status"] == 200 and e["body"]["force"]]
    assert forced and forced[-1]["body"]["old"] == pytest.approx(radius)
    assert forced[-1]["body"]["value"] == pytest.approx(radius * 2)
    assert forced[-1]["body"]["read_back"] == pytest.approx(radius * 2)
    refused = [e for e in entries if e["status"] == 400 and e["target"] == f"vehicle {vid} {GAIN}"]
    assert any(e["body"]["old"] == pytest.approx(before) for e in refused)  # refusals audited with old too
    with up_rig.ground.http(token="ob-token-for-tests") as c:  # an observer cannot write, forced or not
        assert c.put(f"{url}/WPNAV_RADIUS", json={"value": radius, "force": True}).status_code == 403


def test_an_empty_set_sends_nothing_and_a_confirmed_write_is_flown(up_rig: GroundRig, flying: int,
                                                                    tablet: Any, shots: Shots) -> None:
    d, i, vid = tablet, flying - 1, flying
    before = observed(up_rig, i, GAIN)
    writes = len(param_audit(up_rig))
    pick(d, vid)
    d.find_element(By.CSS_SELECTOR, "#vehicle .params summary").click()  # opened: reads the value and range
    rng = d.find_element(By.CSS_SELECTOR, "#vehicle .prange")
    WebDriverWait(d, 20).until(lambda d: "range [0, 200] 1/s" in rng.text, "the range shown")
    name = d.find_element(By.CSS_SELECTOR, "#vehicle .pname")
    assert name.get_attribute("value") == GAIN
    out = d.find_element(By.CSS_SELECTOR, "#vehicle .pout")
    d.find_element(By.CSS_SELECTOR, "#vehicle .pset").click()  # the box is empty
    WebDriverWait(d, 10).until(lambda d: out.get_attribute("data-last") == "refused", "the empty set refused")
    assert "empty" in out.text and d.find_element(By.ID, "dialog").get_attribute("open") is None
    box = d.find_element(By.CSS_SELECTOR, "#vehicle .pval")
    box.send_keys("abc")  # not a number: a number box holds nothing
    d.find_element(By.CSS_SELECTOR, "#vehicle .pset").click()
    assert out.get_attribute("data-last") == "refused"
    assert observed(up_rig, i, GAIN) == pytest.approx(before), "the empty set wrote to the autopilot"
    assert len(param_audit(up_rig)) == writes, "the page sent a write for an empty box"
    # a number: the dialog shows the old and the new value, and the write waits for the operator
    new = round(before * 1.2, 2)
    box.clear()
    box.send_keys(str(new))
    d.find_element(By.CSS_SELECTOR, "#vehicle .pset").click()
    WebDriverWait(d, 20).until(lambda d: d.find_element(By.ID, "dialog").get_attribute("open") is not None,
                               "the confirmation dialog")
    assert float(d.find_element(By.CSS_SELECTOR, "#dialog-body .old").text) == pytest.approx(before, abs=1e-3)
    assert float(d.find_element(By.CSS_SELECTOR, "#dialog-body .new").text) == pytest.approx(new)
    assert GAIN in d.find_element(By.ID, "dialog-title").text
    doc_shot(d, shots, "ui_param_confirm")
    assert observed(up_rig, i, GAIN) == pytest.approx(before), "written before the operator confirmed"
    d.find_element(By.CSS_SELECTOR, "#dialog-buttons button[data-answer='set']").click()
    WebDriverWait(d, 30).until(lambda d: out.get_attribute("data-last") == "set", "the write answered")
    assert observed(up_rig, i, GAIN) == pytest.approx(new, rel=1e-5)  # the autopilot's own value
    doc_shot(d, shots, "ui_param_written")
    with up_rig.ground.http() as c:
        last = [e for e in c.get("/api/audit").json()["entries"] if e["action"] == "param"][-1]
        assert (last["status"], last["body"]["value"]) == (200, pytest.approx(new))
        assert last["body"]["old"] == pytest.approx(before)
        assert c.put(f"/api/vehicles/{vid}/params/{GAIN}", json={"value": before}).status_code == 200


def test_a_vehicle_named_with_html_is_shown_as_text_everywhere(up_rig: GroundRig, tablet: Any,
                                                               shots: Shots) -> None:
    d, vid = tablet, 2
    with up_rig.ground.http() as c:
        url = up_rig.vehicles()[vid]["control_url"]
        r = c.put(f"/api/vehicles/{vid}", json={"name": XSS, "control_url": url})
        assert r.status_code == 200, r.text
    row = f"#fleet tr[data-vehicle='{vid}'] td:nth-child(3)"
    WebDriverWait(d, 20).until(lambda d: d.find_element(By.CSS_SELECTOR, row).text.startswith(XSS),
                               "the name in the fleet list, as text")
    label = f".vmarker[data-vehicle='{vid}'] .label"
    WebDriverWait(d, 20).until(lambda d: d.find_element(By.CSS_SELECTOR, label).text.startswith(XSS),
                               "the name on the map, as text")
    pick(d, vid)
    WebDriverWait(d, 20).until(lambda d: d.find_element(By.CSS_SELECTOR, "#vehicle .vname").text == XSS,
                               "the name in the vehicle panel, as text")
    # a dialog listing the vehicle by name (a command to the ticked vehicles), cancelled
    box = d.find_element(By.CSS_SELECTOR, f"#fleet tr[data-vehicle='{vid}'] input[type=checkbox]")
    box.click()
    try:
        d.find_element(By.ID, "multi-go").click()
        dlg = d.find_element(By.ID, "dialog")
        WebDriverWait(d, 10).until(lambda d: dlg.get_attribute("open") is not None, "the dialog of targets")
        assert XSS in d.find_element(By.CSS_SELECTOR, "#dialog-body .targets").text
        doc_shot(d, shots, "ui_html_name_as_text")
        d.find_element(By.CSS_SELECTOR, "#dialog-buttons button[data-answer='']").click()
    finally:
        box.click()
    where = "#fleet img, .vmarker img, #vehicle img, #dialog img, #confirm img"
    made = d.find_elements(By.CSS_SELECTOR, where)
    assert made == [], "an element was made of the name"
    assert d.execute_script("return window.__xss") is None, "the name ran as code"


def test_every_answer_carries_a_policy_and_the_page_runs_under_it(up_rig: GroundRig, tablet: Any) -> None:
    with up_rig.ground.http() as c:
        for path in ("/", "/static/js/main.js", "/static/app.css", "/api/whoami"):
            csp = c.get(path).headers.get("content-security-policy", "")
            assert "script-src 'self'" in csp and "style-src 'self'" in csp, (path, csp)
            assert "unsafe-inline" not in csp and "unsafe-eval" not in csp and "default-src 'self'" in csp
    tablet.refresh()  # the whole page loaded and run under the policy: not one violation reported
    WebDriverWait(tablet, 30).until(lambda d: d.find_element(By.ID, "link").text == "live")
    WebDriverWait(tablet, 30).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, ".vmarker[data-n]")) == 3)
    violations = [e["message"] for e in tablet.get_log("browser")
                  if "Content Security Policy" in e["message"]]
    assert violations == []


def _layout(d: Any) -> dict[str, float]:
    return d.execute_script("""
        const m = document.getElementById('map').getBoundingClientRect();
        const a = document.querySelector('aside').getBoundingClientRect();
        const e = document.documentElement;
        return {w: innerWidth, h: innerHeight, scrollW: e.scrollWidth, scrollH: e.scrollHeight,
                mapL: m.left, mapR: m.right, mapW: m.width, mapH: m.height, asideL: a.left, asideR: a.right,
                asideW: a.width,
                asideShown: getComputedStyle(document.querySelector('aside')).display !== 'none'};""")


def test_a_tablet_shows_the_map_and_the_panel_and_lists_the_shortcuts(up_rig: GroundRig, tablet: Any,
                                                                      shots: Shots) -> None:
    d = tablet
    pick(d, 1)
    lay = _layout(d)
    assert (lay["w"], lay["h"]) == (WIDTH, HEIGHT), lay
    assert lay["scrollW"] <= lay["w"] and lay["scrollH"] <= lay["h"], f"the page scrolls: {lay}"
    assert lay["asideShown"] and lay["asideR"] <= lay["w"] + 0.5 and lay["asideL"] >= lay["mapR"] - 0.5, lay
    assert lay["mapW"] >= 0.5 * lay["w"] and lay["mapH"] >= 0.6 * lay["h"], f"the map is too small: {lay}"
    doc_shot(d, shots, "ui_tablet_1024x768")
    d.execute_script("document.activeElement && document.activeElement.blur()")
    ActionChains(d).send_keys("?").perform()
    WebDriverWait(d, 10).until(lambda d: d.find_element(By.ID, "help").get_attribute("open") is not None)
    text = d.find_element(By.ID, "help").text
    for key in ("?", "M", "Esc", "W", "R", "Q"):
        assert key in text, (key, text)
    doc_shot(d, shots, "ui_shortcuts")
    ActionChains(d).send_keys(Keys.ESCAPE).perform()
    WebDriverWait(d, 10).until(lambda d: d.find_element(By.ID, "help").get_attribute("open") is None)
    ActionChains(d).send_keys("m").perform()  # map only
    WebDriverWait(d, 10).until(lambda d: not _layout(d)["asideShown"])
    assert math.isclose(_layout(d)["mapW"], lay["w"], abs_tol=1.0)
    ActionChains(d).send_keys("m").perform()
    WebDriverWait(d, 10).until(lambda d: _layout(d)["asideShown"])
    assert _layout(d)["scrollW"] <= lay["w"]
