"""The operator's stick flown: ``taskflight up --vehicles 3`` (tests/up_support.UpRig: models at 3x, companion
processes, the ground service), positions and velocities read from the autopilots by pymavlink ground
stations (not from the service). Seed 000 Sec. VII (the break-in), Sec. IV-C (a stream's validity).

* A slow companion: vehicle 1's control URL is registered behind a proxy that delays every request by
  300 ms (:class:`harness.delay_proxy.DelayProxy`). Paused in flight, the lease taken, stick samples at
  20 Hz move it north; when they stop (the lease released), the vehicle stops within the samples'
  validity, the proxy's delay and its braking, and stays: samples never queue behind the slow answers
  (before: each forward was awaited in the receive loop, so a released stick flew on for seconds).
* Two operators' pages in headless Chromium on the paused vehicle: the first takes the stick and flies
  it; the second shows who holds the stick, offers no "take", and sends nothing (its keys move nothing,
  its own take is refused naming the holder); released, the second sees the stick free. The screenshot
  of the second page (a paused vehicle with the stick lease shown) goes to ``docs/img/`` when
  ``TASKFLIGHT_SCREENSHOTS=docs/img`` is set.
"""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import threading
import time
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest
import yaml

from harness import ROOT
from harness.delay_proxy import DelayProxy
from harness.ground import OPERATOR, OPERATOR2, GroundRig
from harness.team import HOME
from harness.timing import wait_for
from harness.ui import Shots, missing

pytestmark = pytest.mark.integration
log = logging.getLogger(__name__)

SCAN_AND_SEARCH = yaml.safe_load((ROOT / "mission_specs" / "scan_and_search.yaml").read_text())
SCAN_AND_SEARCH["tree"]["children"][2]["params"]["position"][2] = 5.0  # the outdoor platform's 3 m floor
VID, IX = 1, 0  # vehicle 1: the rig's index 0
DELAY_S, VALIDITY_S, SPEED = 0.3, 0.5, 2.0


def local(p: Any) -> tuple[float, float]:
    """(north, east) metres of a (lat, lon, ...) point from the fleet's home."""
    return ((p[0] - HOME[0]) * 111_320.0, (p[1] - HOME[1]) * 111_320.0 * math.cos(math.radians(HOME[0])))


def mission(rig: GroundRig) -> dict[str, Any]:
    return rig.vehicles()[VID]["mission"]


def paused_in_flight(rig: GroundRig) -> None:
    """Vehicle 1 flying a scan, broken into with the joystick routine (a mission given if need be)."""
    if mission(rig).get("state") == "paused" and rig.gcs[IX].armed():
        return
    with rig.ground.http() as c:
        if rig.gcs[IX].armed():
            assert c.post(f"/api/vehicles/{VID}/land").status_code == 200
            wait_for(lambda: not rig.gcs[IX].armed(), rig.wall(90), "vehicle 1 landed (MAVLink)")
        r = c.post(f"/api/vehicles/{VID}/mission", json={**SCAN_AND_SEARCH, "start": True})
        assert r.status_code == 200, r.text
        wait_for(lambda: mission(rig)["node"] == "scan" and (mission(rig)["progress"] or "").startswith(
            "waypoint"), rig.wall(120), lambda: f"the scan under way: {mission(rig)}")
        r = c.post(f"/api/vehicles/{VID}/pause")
        assert r.status_code == 200, r.text
    wait_for(lambda: mission(rig)["state"] == "paused", rig.wall(20), "paused")
    wait_for(lambda: math.hypot(*rig.velocity(IX)[:2]) < 0.3, rig.wall(10), "hovering in the break-in")


def speed(rig: GroundRig) -> float:
    v = rig.velocity(IX)
    return 0.0 if v is None else math.hypot(v[0], v[1])


class Page:
    """A scripted operator's page on the WebSocket: answers the clock exchange like the UI (its clock is
    its own: a fixed offset from the test's), keeps the errors."""

    def __init__(self, rig: GroundRig) -> None:
        self.ws = rig.ground.ws(OPERATOR)
        self.errors: list[dict[str, Any]] = []
        self.synced = threading.Event()
        self._stop = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    @staticmethod
    def now_ms() -> float:
        return (time.monotonic() + 1234.5) * 1000.0

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                m = json.loads(self.ws.recv(timeout=0.2))
            except TimeoutError:
                continue
            except Exception:
                return
            if m["type"] == "clock":
                self.ws.send(json.dumps({"type": "clock", "t": m["t"], "page_t": self.now_ms()}))
                self.synced.set()
            elif m["type"] == "error":
                self.errors.append(m)

    def close(self) -> None:
        self._stop.set()
        self._reader.join(2)
        self.ws.close()


def test_the_released_stick_stops_the_vehicle_when_the_companion_answers_slowly(up_rig: GroundRig) -> None:
    rig = up_rig
    paused_in_flight(rig)
    url, name = rig.vehicles()[VID]["control_url"], rig.vehicles()[VID]["name"]
    target = urlsplit(url)
    proxy = DelayProxy(target.hostname or "127.0.0.1", target.port or 80, DELAY_S)
    page: Page | None = None
    try:
        with rig.ground.http() as c:
            r = c.put(f"/api/vehicles/{VID}", json={"name": name, "control_url": proxy.url})
            assert r.status_code == 200, r.text
            r = c.post(f"/api/vehicles/{VID}/stick/lease")
            assert r.status_code == 200, r.text
            lease = r.json()["lease_id"]
        page = Page(rig)
        assert page.synced.wait(10), "the service never asked the page for its clock"
        start = local(rig.position(IX))

        def moved() -> float:
            return local(rig.position(IX))[0] - start[0]

        seq, end = 0, time.monotonic() + rig.wall(30)
        while time.monotonic() < end and moved() < 6.0:
            seq += 1
            page.ws.send(json.dumps({"type": "joystick", "vehicle": VID, "lease": lease, "seq": seq,
                                     "values": [SPEED, 0, 0, 0], "validity_s": VALIDITY_S,
                                     "t": page.now_ms()}))
            time.sleep(0.05)
        released_at, released_pos = time.monotonic(), local(rig.position(IX))
        with rig.ground.http() as c:  # the operator lets go: no more samples, the lease released
            assert c.delete(f"/api/vehicles/{VID}/stick/lease", params={"lease_id": lease}).status_code == 200
        assert moved() >= 6.0, f"moved {moved():.1f} m north in {seq} samples: {page.errors[:3]}"
        assert proxy.requests > seq / 4, "the samples did not go through the slow proxy"
        # stopped: within the validity, the proxy's delay and braking (autopilot time: x speed-up)
        wait_for(lambda: speed(rig) < 0.3, rig.wall(20), lambda: f"stopped; speed {speed(rig):.2f} m/s")
        stop_wall = time.monotonic() - released_at
        stopped_pos = local(rig.position(IX))
        after = math.dist(released_pos, stopped_pos)
        time.sleep(1.5)
        drift = math.dist(stopped_pos, local(rig.position(IX)))
        # flown after the last sample: at most SPEED for validity + the proxy's delay (autopilot seconds),
        # then braking (< 3 m from 2 m/s); a queue of late samples flies on for tens of metres
        bound = SPEED * (VALIDITY_S + DELAY_S * rig.speedup) + 3.0
        log.info("stick released behind a %.0f ms proxy: stopped %.2f s (wall) after the last sample, "
                 "%.2f m flown after it (bound %.1f m), %d samples, %d requests through the proxy",
                 DELAY_S * 1000, stop_wall, after, bound, seq, proxy.requests)
        assert after <= bound, f"flew {after:.1f} m after the stick was released (bound {bound:.1f} m)"
        assert drift < 0.5, f"drifting {drift:.2f} m without samples"
    finally:
        if page is not None:
            page.close()
        with rig.ground.http() as c:
            c.put(f"/api/vehicles/{VID}", json={"name": name, "control_url": url})
        proxy.close()


def _doc_shot(driver: Any, shots: Shots, name: str) -> None:
    path = shots(driver, name)
    docs = os.environ.get("TASKFLIGHT_SCREENSHOTS")
    if docs:
        Path(docs).mkdir(parents=True, exist_ok=True)
        shutil.copy(path, Path(docs) / f"{name}.png")


def test_a_second_operator_page_cannot_fly_a_leased_vehicle(up_rig: GroundRig,
                                                           tmp_path_factory: pytest.TempPathFactory) -> None:
    if missing():
        pytest.skip(missing() or "")
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    from harness.ui import browser, login

    rig = up_rig
    paused_in_flight(rig)
    shots = Shots(tmp_path_factory.mktemp("stick_screenshots"))
    pages = []
    try:
        for token in (OPERATOR, OPERATOR2):
            d = browser()
            pages.append(d)
            login(d, rig.ground.url, token)
            row = f"#fleet tr[data-vehicle='{VID}']"
            WebDriverWait(d, 30).until(lambda d: d.find_elements(By.CSS_SELECTOR, row))  # noqa: B023
            d.find_element(By.CSS_SELECTOR, row).click()
            # paused: the stick panel shown, nothing sent until the stick is taken
            WebDriverWait(d, 30).until(lambda d: d.find_element(By.CSS_SELECTOR, ".joystick").is_displayed(),
                                       "the paused vehicle's stick panel")
        one, two = pages
        time.sleep(0.5)
        assert [d.execute_script("return window.taskflight.joystick.sent") for d in pages] == [0, 0]
        one.find_element(By.CSS_SELECTOR, ".jtake").click()
        WebDriverWait(one, 20).until(lambda d: d.find_element(By.CSS_SELECTOR, ".jlease").get_attribute(
            "data-holder") == "me", "the first page holds the stick")
        # the second page: who holds it, no take button, its keys send nothing, its take refused
        WebDriverWait(two, 20).until(lambda d: d.find_element(By.CSS_SELECTOR, ".jlease").get_attribute(
            "data-holder").startswith("operator:"), "the lease shown on the second page")
        assert "held by operator:" in two.find_element(By.CSS_SELECTOR, ".jlease").text
        assert not two.find_element(By.CSS_SELECTOR, ".jtake").is_displayed()
        _doc_shot(two, shots, "stick-lease")
        start = local(rig.position(IX))
        ActionChains(two).key_down("w").perform()
        time.sleep(1.0)
        ActionChains(two).key_up("w").perform()
        took = two.execute_async_script(
            "const done = arguments[arguments.length - 1];"
            f"const j = window.taskflight.joystick; j.engage({VID}).then((ok) => done([ok, j.status]));")
        assert took[0] is False and "held by operator:" in took[1], took
        assert two.execute_script("return window.taskflight.joystick.sent") == 0
        assert math.dist(start, local(rig.position(IX))) < 1.0, "the second page moved the vehicle"
        # the holder flies it north with the keyboard
        ActionChains(one).key_down("w").perform()
        try:
            wait_for(lambda: local(rig.position(IX))[0] - start[0] > 3.0, rig.wall(24),
                     "moved north by the holder", poll_s=0.1)
        finally:
            ActionChains(one).key_up("w").perform()
        assert one.execute_script("return window.taskflight.joystick.sent") > 15
        assert two.execute_script("return window.taskflight.joystick.sent") == 0
        one.find_element(By.CSS_SELECTOR, ".jrelease").click()
        WebDriverWait(two, 20).until(lambda d: d.find_element(By.CSS_SELECTOR, ".jtake").is_displayed(),
                                     "the stick free again on the second page")
        assert "stick free" in two.find_element(By.CSS_SELECTOR, ".jlease").text
    finally:
        for d in pages:
            d.quit()
