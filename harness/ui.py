"""Debian's headless Chromium driven by selenium for the web UI's tests and bench.

No browser is downloaded: ``/usr/bin/chromium`` and ``/usr/bin/chromedriver`` (``apt-get install chromium
chromium-driver``, done by ``scripts/test`` when missing). The performance log records every request the
page makes (CDP ``Network.requestWillBeSent``), so a test can prove that nothing left the machine.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")


def missing() -> str | None:
    """Why the browser tests cannot run (None when they can)."""
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (pip install -e '.[dev]')"
    for p in (CHROMIUM, CHROMEDRIVER):
        if not p.exists():
            return f"{p} not found: apt-get install chromium chromium-driver (scripts/test does it as root)"
    return None


def browser(width: int = 1400, height: int = 900) -> Any:
    """A headless Chromium with the performance (network) log on."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
              f"--window-size={width},{height}", "--disable-background-networking", "--no-first-run",
              "--disable-component-update", "--disable-default-apps", "--disable-sync",
              "--disable-background-timer-throttling", "--disable-renderer-backgrounding"):
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"performance": "ALL", "browser": "ALL"})
    return webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=opts)


def requested_urls(driver: Any) -> list[str]:
    """Every URL the page requested since the last call (the CDP network events of the performance log)."""
    urls = []
    for entry in driver.get_log("performance"):
        msg = json.loads(entry["message"])["message"]
        if msg.get("method") in ("Network.requestWillBeSent", "Network.webSocketCreated"):
            p = msg["params"]
            urls.append(p["request"]["url"] if "request" in p else p["url"])
    return urls


def foreign(urls: list[str], service_url: str) -> list[str]:
    """The URLs not on the service's host (data: and blob: stay in the page)."""
    host = urlsplit(service_url).netloc
    return [u for u in urls if urlsplit(u).scheme not in ("data", "blob") and urlsplit(u).netloc != host]


def login(driver: Any, url: str, token: str, timeout: float = 30.0) -> None:
    """Open the UI and log in through its form; wait until the live stream is up."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get(url + "/")
    driver.execute_script("sessionStorage.clear()")
    driver.get(url + "/")
    wait = WebDriverWait(driver, timeout)
    box = wait.until(ec.visibility_of_element_located((By.ID, "token")))
    box.send_keys(token)
    driver.find_element(By.CSS_SELECTOR, "#login button[type=submit]").click()
    wait.until(lambda d: d.find_element(By.ID, "link").text == "live")


class Shots:
    """Screenshots of each step: under ``directory`` and, if env TASKFLIGHT_ARTEFACTS is set, there too."""

    def __init__(self, directory: Path) -> None:
        self.dir = directory
        self.dir.mkdir(parents=True, exist_ok=True)
        extra = os.environ.get("TASKFLIGHT_ARTEFACTS")
        self.extra = Path(extra) / "ui" if extra else None

    def __call__(self, driver: Any, name: str) -> Path:
        path = self.dir / f"{time.strftime('%H%M%S')}_{name}.png"
        driver.save_screenshot(str(path))
        if self.extra is not None:
            self.extra.mkdir(parents=True, exist_ok=True)
            shutil.copy(path, self.extra / path.name)
        return path


@contextmanager
def operator_page(url: str, token: str, vehicles: int, urls: list[str]) -> Iterator[Any]:
    """A headless browser logged in to the ground service at ``url`` once its fleet list shows
    ``vehicles`` rows; on leaving, every URL the page requested is added to ``urls`` and the browser quits."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    d = browser()
    try:
        login(d, url, token)
        WebDriverWait(d, 30).until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#fleet tbody tr"))
                                   == vehicles)
        yield d
    finally:
        urls.extend(requested_urls(d))
        d.quit()
