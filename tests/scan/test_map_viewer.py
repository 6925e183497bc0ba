"""The real Rerun viewer draws the scan map with y up, inside its axes frame, beside its legend (Xvfb, ~25 s)."""

from __future__ import annotations

import numpy as np
import pytest
from viewer_shot import RERUN, XVFB, screenshot

from dicetrace.ics import Grid
from dicetrace.scan import label_grid, scan
from dicetrace.scan.map_rrd import AXIS_RGB, BACKGROUND_RGB, legend_order, write_scan_rrd
from dicetrace.scan.colours import OUTCOME_RGB

pytestmark = [pytest.mark.viewer, pytest.mark.slow]


def _runs(mask: np.ndarray, axis: int, frac: float) -> np.ndarray:
    """Indices of the rows (axis=1) or columns (axis=0) where ``mask`` holds on more than ``frac`` of them."""
    return np.flatnonzero(mask.mean(axis=axis) > frac)


@pytest.mark.skipif(XVFB is None, reason="xvfb-run not on PATH")
@pytest.mark.skipif(RERUN is None, reason="rerun CLI not installed")
@pytest.mark.long
def test_the_viewer_shows_the_map_upright_framed_and_with_its_legend(tmp_path):
    from PIL import Image

    nx, ny = 24, 16
    out = tmp_path / "s"
    scan(Grid("seed", "red-sea", (nx, ny)), out)
    rrd = tmp_path / "map.rrd"
    write_scan_rrd(out, rrd)
    png = screenshot(rrd, tmp_path)
    im = np.asarray(Image.open(png).convert("RGB")).astype(int)
    h, w, _ = im.shape

    view = im[int(0.08 * h): int(0.95 * h)]
    assert (np.abs(view - np.array(BACKGROUND_RGB)).sum(axis=-1) <= 6).mean() > 0.3, "grey background missing"
    # the frame: the longest light-grey rows and columns
    axis = np.abs(im - np.array(AXIS_RGB)).sum(axis=-1) <= 30
    cols, rows = _runs(axis, 0, 0.25), _runs(axis, 1, 0.2)
    assert len(cols) >= 2 and len(rows) >= 2, "no axes frame"
    left, right, top, bottom = cols.min(), cols.max(), rows.min(), rows.max()
    assert right - left > 0.2 * w and bottom - top > 0.2 * h
    # every cell's centre on screen has its outcome's colour, y up: row 0 of the screen is the grid's last j
    grid = label_grid(out)
    cw, ch = (right - left) / nx, (bottom - top) / ny
    rgb = {o: np.array(c) for o, c in OUTCOME_RGB.items()}

    def colour_at(i, j_from_top):
        y, x = int(top + (j_from_top + 0.5) * ch), int(left + (i + 0.5) * cw)
        return im[y, x]

    upright = np.mean([np.abs(colour_at(i, ny - 1 - j) - rgb[int(grid[i, j])]).sum() <= 40
                       for i in range(nx) for j in range(ny)])
    flipped = np.mean([np.abs(colour_at(i, j) - rgb[int(grid[i, j])]).sum() <= 40
                       for i in range(nx) for j in range(ny)])
    assert upright > 0.95 and flipped < 0.6, (upright, flipped)
    # the legend, right of the frame: a swatch of each outcome present, top to bottom
    strip = im[top:bottom, right + 5:]
    for o in legend_order(set(np.unique(grid).tolist())):
        found = (np.abs(strip - rgb[o]).sum(axis=-1) <= 20).sum()
        assert found > 100, f"no legend swatch for outcome {o}"
