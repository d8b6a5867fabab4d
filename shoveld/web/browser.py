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


def open_browser(width: int = 1280, height: int = 800) -> Any:
    """A headless Chromium at the cab panel's size (10-inch, 1280 x 800)."""
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
    return driver
