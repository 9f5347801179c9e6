"""The operator's screen never looks live when it is not (headless Chromium on a real fleet).

A fleet of 3 models, 3 companion processes on a team link and ``taskflight ground`` as a process
(harness.ground.GroundRig, so that a companion and the service can be killed), Debian's Chromium driven by
selenium:

* a vehicle whose companion is killed greys out and says "lost" in the fleet list and on the map within
  the lost time (:data:`groundstation.fleet.LOST_S`), the others stay live;
* the link-lost alert is in the list of a page opened afterwards (the history from the service), an
  acknowledgement on one page shows on the other without a reload, and after a reload;
* the header turns from "live" to "stale" when no snapshot arrived for 2 s: the service stopped
  (SIGSTOP: the socket stays open) and killed; it is "live" again once the service answers.

With ``TASKFLIGHT_SCREENSHOTS=docs/img`` the lost vehicle's screenshot is written there
(``ui-lost-vehicle.png``).
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from harness.ui import Shots, browser, login, missing

if missing():
    pytest.skip(missing() or "", allow_module_level=True)

from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

from groundstation.fleet import LOST_S
from harness.ground import OPERATOR, GroundRig
from harness.timing import wait_for

pytestmark = pytest.mark.integration

#: the screen's slack over the lost time: a snapshot period, a poll period and a frame
SLACK_S = 3.0


@pytest.fixture(scope="module")
def live_page(ground_rig: GroundRig) -> Iterator[Any]:
    d = browser()
    try:
        login(d, ground_rig.ground.url, OPERATOR)
        WebDriverWait(d, 30).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#fleet tbody tr")) == 3)
        yield d
    finally:
        d.quit()


def row(d: Any, vid: int) -> Any:
    return d.find_element(By.CSS_SELECTOR, f'#fleet tr[data-vehicle="{vid}"]')


def marker(d: Any, vid: int) -> Any:
    return d.find_element(By.CSS_SELECTOR, f'.vmarker[data-vehicle="{vid}"]')


def shown_lost(d: Any, vid: int) -> bool:
    r, m = row(d, vid), marker(d, vid)
    return ("lost" in r.get_attribute("class").split() and "lost" in r.text
            and "lost" in m.get_attribute("class").split() and "lost" in m.text)


def test_a_killed_vehicle_greys_out_and_says_lost(ground_rig: GroundRig, live_page: Any,
                                                  shots: Shots) -> None:
    d = live_page
    wait_for(lambda: all(row(d, v).get_attribute("data-link") == "live" for v in (1, 2, 3)), 30,
             "every vehicle live on the page")
    proc = ground_rig.companions[2]
    assert proc is not None
    proc.kill()
    proc.wait(10)
    killed = time.monotonic()
    wait_for(lambda: shown_lost(d, 3), LOST_S + 20, "vehicle 3 shown lost in the list and on the map")
    took = time.monotonic() - killed
    assert took <= LOST_S + SLACK_S, f"vehicle 3 shown lost {took:.1f} s after its companion was killed"
    for vid in (1, 2):
        assert row(d, vid).get_attribute("data-link") == "live" and "lost" not in marker(d, vid).text
    assert float(row(d, 3).text.split("lost")[-1].split()[0]) > LOST_S  # its age is shown with it
    shots(d, "lost_vehicle")
    target = os.environ.get("TASKFLIGHT_SCREENSHOTS")
    if target:
        Path(target).mkdir(parents=True, exist_ok=True)
        d.save_screenshot(str(Path(target) / "ui-lost-vehicle.png"))


def test_alert_history_after_a_reload_and_an_acknowledgement_every_operator_sees(
        ground_rig: GroundRig, live_page: Any) -> None:
    d = live_page
    lost = '#alerts li[data-kind="link_lost"]'
    wait_for(lambda: any("vehicle 3" in li.text or "(3)" in li.text
                         for li in d.find_elements(By.CSS_SELECTOR, lost)), 30,
             "vehicle 3's link-lost alert listed")
    other = browser()
    try:
        login(other, ground_rig.ground.url, OPERATOR)  # a page opened after the alert: the history
        wait_for(lambda: len(other.find_elements(By.CSS_SELECTOR, lost)) >= 1, 30, "the alert in the history")
        li = d.find_elements(By.CSS_SELECTOR, lost)[0]
        eid = li.get_attribute("data-event")
        li.find_element(By.CSS_SELECTOR, "button.ack").click()
        sel = f'#alerts li[data-event="{eid}"]'
        for page_ in (d, other):  # the other page without a reload (the "ack" message on its socket)
            wait_for(lambda p=page_: "acknowledged by operator" in p.find_element(By.CSS_SELECTOR, sel).text,
                     15, "the acknowledgement shown")
        other.refresh()
        wait_for(lambda: other.find_elements(By.CSS_SELECTOR, sel)
                 and "acked" in other.find_element(By.CSS_SELECTOR, sel).get_attribute("class").split(), 30,
                 "the acknowledgement after a reload")
        with ground_rig.ground.http() as c:
            alert = next(a for a in c.get("/api/alerts").json()["alerts"] if str(a["id"]) == eid)
            assert alert["acked_by"].startswith("operator")
            assert any(e["action"] == "ack" for e in c.get("/api/audit").json()["entries"])
    finally:
        other.quit()


def test_the_header_says_stale_when_the_service_stops(ground_rig: GroundRig, live_page: Any,
                                                      shots: Shots) -> None:
    d = live_page
    state = lambda: d.find_element(By.ID, "link").get_attribute("data-state")  # noqa: E731
    wait_for(lambda: state() == "live", 30, "the header live")
    ground = ground_rig.ground
    assert ground.proc is not None
    ground.proc.send_signal(signal.SIGSTOP)  # hung: the socket stays open, nothing arrives
    try:
        wait_for(lambda: state() == "stale", 15, "the header stale while the service is stopped")
        assert "stale" in d.find_element(By.ID, "link").text
        shots(d, "service_stopped")
    finally:
        ground.proc.send_signal(signal.SIGCONT)
    wait_for(lambda: state() == "live", 30, "the header live again")
    ground.kill()
    wait_for(lambda: state() == "stale", 15, "the header stale once the service is killed")
    ground.start()
    wait_for(lambda: state() == "live", 60, "the header live once the service answers again")
