"""A real browser for the live view's tests and pictures: Debian's Chromium, headless,
driven by Playwright; and the fish it shows, found by colour."""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

CHROMIUM = os.environ.get("FISHSWARM_CHROMIUM", "/usr/bin/chromium")
"""The browser (Debian's package ``chromium``)."""

CHROMIUM_FLAGS = (
    "--no-sandbox",  # tests run as root here
    "--no-first-run",
    "--disable-quic",
    "--disable-sync",
    "--disable-component-update",
    # Without these Chromium keeps trying to reach the outside; this machine has no route.
    "--disable-background-networking",
    # No GPU: WebGL on Chromium's software rasterizer.
    "--enable-unsafe-swiftshader",
    "--use-angle=swiftshader",
)

WIDTH, HEIGHT = 1280, 800


def browser_missing() -> str | None:
    """Why no browser test can run here (None when one can)."""
    if shutil.which(CHROMIUM) is None and not Path(CHROMIUM).exists():
        return f"no Chromium at {CHROMIUM} (apt-get install chromium)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "no Playwright (pip install playwright)"
    return None


@contextlib.contextmanager
def open_page(url: str) -> Iterator[Any]:
    """A headless Chromium tab showing ``url``."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as driver:
        browser = driver.chromium.launch(
            executable_path=CHROMIUM, args=list(CHROMIUM_FLAGS), headless=True
        )
        try:
            page = browser.new_page(viewport={"width": WIDTH, "height": HEIGHT})
            page.goto(url, timeout=60_000)
            yield page
        finally:
            browser.close()


def screenshot(page: Any, path: Path) -> NDArray[np.uint8]:
    """Save what the tab shows to ``path`` (PNG) and return it as (H, W, 3) RGB. A capture
    the browser refuses while busy ("Unable to capture screenshot", seen on a loaded
    2-core machine) is tried again, at most three times in all."""
    import matplotlib.image
    from playwright.sync_api import Error

    for attempt in range(3):
        try:
            page.screenshot(path=str(path))
            break
        except Error as error:
            if "Unable to capture screenshot" not in str(error) or attempt == 2:
                raise
            time.sleep(1.0)
    image = matplotlib.image.imread(str(path))
    return np.asarray(np.round(image[..., :3] * 255), dtype=np.uint8)


def fish_pixels(image: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """Where the tank panel (the left three fifths, below the top bar, right of where the
    viewer's list of sources stands) shows fish: strongly coloured pixels; the tank's walls,
    the floor's grid and the background are grey. The list is left out: the viewer's
    welcome page, shown while it loads, marks its selected entry in blue there (seen as
    fish before the recording came, once, on a loaded machine)."""
    rgb = image.astype(np.int16)
    vivid = (rgb.max(axis=2) - rgb.min(axis=2)) > 80
    panel = np.zeros_like(vivid)
    height, width = vivid.shape
    panel[int(0.08 * height) : int(0.95 * height), int(0.16 * width) : int(0.58 * width)] = True
    found: NDArray[np.bool_] = vivid & panel
    return found


def wait_for_fish(page: Any, path: Path, *, least: int = 200, timeout: float = 120.0) -> None:
    """Wait until the tab shows at least ``least`` fish pixels (the viewer's WebAssembly
    loads, connects and draws: seconds on a software rasterizer)."""
    deadline = time.monotonic() + timeout
    while int(fish_pixels(screenshot(page, path)).sum()) < least:
        if time.monotonic() > deadline:
            raise TimeoutError(f"no fish drawn after {timeout:g} s (see {path})")
        time.sleep(1.0)
