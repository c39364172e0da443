"""Reading the status pages as a person sees them: a screenshot's pixels and the page's text
positions, for the Chromium tests of tests/http and tests/relay (issue 50, item 3)."""

from __future__ import annotations

import io
from typing import Any

from tests.helpers import ROOT

ARTIFACTS = ROOT / "tests" / "artifacts"

OVERFLOW = ("return [document.documentElement.scrollWidth, window.innerWidth,"
            " Math.max(...Array.from(document.querySelectorAll('.scroll'))"
            ".map((d) => d.scrollWidth - d.clientWidth))]")
"""The page's width against the window's, and the most any table box scrolls sideways."""


def shot(driver: Any, name: str) -> Any:
    """Save the window's screenshot as ``tests/artifacts/<name>.png`` and return it as an
    RGB image (Pillow)."""
    from PIL import Image

    ARTIFACTS.mkdir(exist_ok=True)
    png = driver.get_screenshot_as_png()
    (ARTIFACTS / f"{name}.png").write_bytes(png)
    return Image.open(io.BytesIO(png)).convert("RGB")


def coloured_pixels(image: Any, box: dict[str, float], rgb: tuple[int, int, int],
                    scale: float = 1.0, tolerance: int = 40) -> int:
    """How many pixels inside ``box`` (a getBoundingClientRect, CSS pixels) are within
    ``tolerance`` of ``rgb`` in the screenshot ``image``."""
    left, top = int(box["left"] * scale), int(box["top"] * scale)
    right, bottom = int(box["right"] * scale), int(box["bottom"] * scale)
    found = 0
    for r, g, b in image.crop((left, top, right, bottom)).get_flattened_data():
        if abs(r - rgb[0]) + abs(g - rgb[1]) + abs(b - rgb[2]) <= tolerance:
            found += 1
    return found
