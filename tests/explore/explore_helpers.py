"""Helpers of the explorer tests: a small view of the seed slice, map PNGs decoded, scans to compare with, a page's map."""

from __future__ import annotations

import io

import numpy as np

#: A small window inside red sea (five or six faces at 16×16) and its resolution.
WINDOW = "1.4,1.56,3.95,4.25"
RES = 16


def png_outcomes(content: bytes) -> np.ndarray:
    """The outcome grid [i, j] of a map PNG (its colours decoded)."""
    from PIL import Image

    from dicetrace.explore.app import outcome_from_rgb

    img = np.asarray(Image.open(io.BytesIO(content)).convert("RGB"))
    out = outcome_from_rgb(img)
    assert (out != -9).all(), "a pixel of the map has no outcome's colour"
    return out


def scan_outcomes(tmp_path, window: str, res, name: str = "scan", **options) -> np.ndarray:
    """What ``dicetrace scan`` writes for that window and resolution, as a label grid."""
    from dicetrace.ics import Grid, get_window
    from dicetrace.scan import label_grid, scan

    folder = tmp_path / name
    scan(Grid("seed", get_window(window), res), folder, **options)
    return label_grid(folder)


def wait_ready(page, timeout=120_000):
    """Wait until the page (or frame) has its refined map, or shows an error (then fail with it)."""
    page.wait_for_function("document.body.dataset.state === 'ready' || document.body.dataset.state === 'error'",
                           timeout=timeout)
    assert page.evaluate("document.body.dataset.state") == "ready", page.inner_text("#error")


def page_outcomes(page) -> np.ndarray:
    """The outcome grid [i, j] of the map the page (or frame) shows, read from its canvas."""
    from dicetrace.explore.app import outcome_from_rgb

    data = page.evaluate("""() => {
        const c = document.getElementById('map');
        return {w: c.width, h: c.height, px: Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data)};
    }""")
    img = np.array(data["px"], dtype=np.uint8).reshape(data["h"], data["w"], 4)[..., :3]
    out = outcome_from_rgb(img)
    assert (out != -9).all()
    return out


def shift_click(page, box, fx: float, fy: float) -> list:
    """Shift-click the map at fraction (fx, fy) of its box and wait for the second pick; the picked throws."""
    page.keyboard.down("Shift")
    page.mouse.click(box["x"] + box["width"] * fx, box["y"] + box["height"] * fy)
    page.keyboard.up("Shift")
    page.wait_for_function("JSON.parse(document.getElementById('info').dataset.throws || '[]').length === 2",
                           timeout=60_000)
    return page.evaluate("JSON.parse(document.getElementById('info').dataset.throws)")
