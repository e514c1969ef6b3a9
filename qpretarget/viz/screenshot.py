# SPDX-License-Identifier: Apache-2.0
"""Screenshots of the browser viewer with headless Chromium (selenium + Debian's chromium).

Used by the viewer test and by ``scripts/make_media.py``; needs ``selenium`` and the ``chromium``
and ``chromium-driver`` packages (``.ci/run`` installs them).
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path

from ..errors import QPRetargetError, missing_dependency

CHROMIUM_ARGS = (
    "--headless=new", "--no-sandbox", "--disable-gpu", "--use-gl=angle", "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader", "--disable-background-networking", "--disable-component-update",
    "--disable-sync", "--no-first-run",
)  # fmt: skip


def headless_chrome(width: int = 1000, height: int = 700):  # noqa: ANN201
    """A selenium driver on headless Chromium with software WebGL."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        raise missing_dependency("test", "screenshots (selenium)") from None
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver_path = shutil.which("chromedriver")
    if not (chromium and driver_path):
        raise QPRetargetError(
            "screenshots need Chromium and its driver: `apt-get install chromium chromium-driver`."
        )
    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for a in (*CHROMIUM_ARGS, f"--window-size={width},{height}"):
        opts.add_argument(a)
    return webdriver.Chrome(service=Service(driver_path), options=opts)


def screenshot(url: str, out: str | Path, *, wait_for: tuple[str, ...] = (), settle: float = 3.0,
               timeout: float = 90.0, width: int = 1000, height: int = 700) -> bool:  # fmt: skip
    """Load ``url``, wait until every text of ``wait_for`` is on the page, save a PNG.

    Returns:
        ``True`` when every awaited text appeared before ``timeout``.
    """
    driver = headless_chrome(width, height)
    try:
        driver.get(url)
        deadline = time.time() + timeout
        found = not wait_for
        while not found and time.time() < deadline:
            src = driver.page_source
            found = all(w in src for w in wait_for)
            if not found:
                time.sleep(1.0)
        time.sleep(settle)
        driver.save_screenshot(str(out))
    finally:
        driver.quit()
    return found
