"""Headless Chromium for the page tests, the screenshots and the latency bench.

Debian's ``chromium`` and ``chromium-driver`` (installed by ``.ci/run``), driven by
Selenium. The flags keep it off the network: this machine has none, and Chromium
otherwise keeps trying to reach Google's services.
"""

from __future__ import annotations

import shutil
import tempfile
from typing import Any

CHROMIUM = ("/usr/bin/chromium", "/usr/bin/chromium-browser")
CHROMEDRIVER = "/usr/bin/chromedriver"


def find_chromium() -> str | None:
    for path in CHROMIUM:
        if shutil.which(path):
            return path
    return None


def open_browser(width: int = 1280, height: int = 800, touch: bool = False) -> Any:
    """A headless Chromium at the cab panel's size (10-inch, 1280 x 800); ``touch``: a
    touch screen's, as the cab's panel is (see :func:`tap`)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    binary = find_chromium()
    if binary is None or not shutil.which(CHROMEDRIVER):
        raise RuntimeError("Chromium and its driver are needed: apt-get install chromium "
                           "chromium-driver (.ci/run does)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = binary
    profile = tempfile.mkdtemp(prefix="shoveld-chromium-")
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage",
                 f"--window-size={width},{height}", f"--user-data-dir={profile}"):
        opts.add_argument(flag)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    # The page area itself at the panel's size (the window size counts the browser's frame).
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                           {"width": width, "height": height, "deviceScaleFactor": 1,
                            "mobile": False})
    if touch:
        driver.execute_cdp_cmd("Emulation.setTouchEmulationEnabled",
                               {"enabled": True, "maxTouchPoints": 5})
    return driver


def tap(driver: Any, selector: str) -> None:
    """A finger's tap on the middle of the first element ``selector`` finds: a touch
    start and end through Chromium's input pipeline, as a panel sends them (Chromium
    makes the page's touch events, and a click of the tap, as on a touch screen). The
    point is read and tapped at once, so a page that draws the element again between
    is tapped where it stands, where a WebDriver element would be stale."""
    x, y = driver.execute_script(
        "const r = document.querySelector(arguments[0]).getBoundingClientRect();"
        "return [r.left + r.width / 2, r.top + r.height / 2]", selector)
    point = {"x": x, "y": y, "radiusX": 4, "radiusY": 4, "force": 1}
    driver.execute_cdp_cmd("Input.dispatchTouchEvent",
                           {"type": "touchStart", "touchPoints": [point]})
    driver.execute_cdp_cmd("Input.dispatchTouchEvent", {"type": "touchEnd", "touchPoints": []})
