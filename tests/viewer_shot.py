"""The real Rerun viewer's screenshot of a recording, headless under Xvfb (shared by the viewer tests)."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

RERUN_CLI = Path(sys.executable).parent / "rerun"
XVFB = shutil.which("xvfb-run")
RERUN = str(RERUN_CLI) if RERUN_CLI.exists() else shutil.which("rerun")


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def screenshot(rrd: Path, folder: Path, size: tuple[int, int] = (1400, 900)) -> Path:
    """The viewer's screenshot of ``rrd`` in a window of ``size`` (default 1400x900) under Xvfb (``folder/shot.png``).

    Each viewer gets a port of its own: with one port, a second screenshot at the same time
    (pytest -n 2) hands its recording to the first viewer, and ``--new`` (pick a free port)
    races when two viewers start together ("Address already in use").  A port taken in the
    instant between picking and binding is retried once.
    """
    png = folder / "shot.png"
    env = {**os.environ, "XDG_RUNTIME_DIR": str(folder)}
    for attempt in range(2):
        w, h = size
        cmd = [XVFB, "-a", "-s", f"-screen 0 {w}x{h}x24", RERUN, str(rrd), "--port", str(_free_port()),
               "--screenshot-to", str(png), "--window-size", f"{w}x{h}"]
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env, cwd=folder)
        if res.returncode == 0 or "Address already in use" not in res.stderr:
            break
    assert res.returncode == 0, res.stderr[-2000:]
    return png


# -- finding the dice on a screenshot of a recording's 3-D view -------------------------------------------------------

#: The 3-D view's background (``sinks.rerun_view.default_blueprint``) and the ground's colour and its grid's.
VIEW_BACKGROUND = (250, 250, 250)
GROUND = ((120, 150, 120), (95, 120, 95))


def of_colour(img, colour, tol: float = 0.12):
    """Pixels of ``colour`` however the viewer shades it: the same chromaticity, saturated."""
    import numpy as np

    img = np.asarray(img, dtype=float)
    colour = np.asarray(colour, dtype=float)
    chroma = img / np.maximum(img.sum(axis=-1, keepdims=True), 1)
    return (np.abs(chroma - colour / colour.sum()).sum(axis=-1) < tol) & (img.max(axis=-1) - img.min(axis=-1) > 60)


def view3d_rect(img, right: int) -> tuple[int, int, int, int] | None:
    """(top, bottom, left, right) of a recording's 3-D view in a screenshot, pixel rows and columns inclusive: the
    rows, then the columns, left of column ``right`` (the view is the layout's left column) that are mostly its
    background or its ground (the viewer's bars above and below it, and the panels beside it, may have a few pixels
    of the background's grey); None where nothing of it is drawn yet."""
    import numpy as np

    sub = np.asarray(img)[:, :right, :3].astype(int)
    mask = (sub == VIEW_BACKGROUND).all(axis=-1)
    for g in GROUND:
        mask |= np.abs(sub - g).sum(axis=-1) <= 12
    rows = np.flatnonzero(mask.mean(axis=1) > 0.5)
    if len(rows) == 0:
        return None
    cols = np.flatnonzero(mask[rows[0] : rows[-1] + 1].mean(axis=0) > 0.5)
    return int(rows[0]), int(rows[-1]), int(cols[0]), int(cols[-1])


def dice_in_view(img, colours, right: int, *, min_px: int = 150, margin: int = 3) -> dict:
    """Each die's pixels and where they are against the 3-D view: {name: (pixels, (top, bottom, left, right) of the
    die, room to the view's edges (top, bottom, left, right) in pixels)}.

    ``colours``: {name: one colour or a list of them}, the die's (a compare die's rim, or a single die's face
    plates).  Thin things of those colours (a path, its drop rising out of the view) are left out by an opening of
    the mask; what is left is the die.  A die cut by the view's edge shows as room 0 or less.
    """
    import numpy as np
    from scipy import ndimage

    img = np.asarray(img)[..., :3].astype(int)
    rect = view3d_rect(img, right)
    if rect is None:
        return {name: (0, None, None) for name in colours}
    top, bottom, left, right_edge = rect
    out = {}
    for name, cols in colours.items():
        cols = [cols] if np.ndim(cols) == 1 else cols
        mask = np.zeros(img.shape[:2], dtype=bool)
        for c in cols:
            mask |= of_colour(img, c)
        inside = np.zeros_like(mask)
        inside[top : bottom + 1, left : right_edge + 1] = True
        mask &= inside  # the viewer's own bars and buttons (a blue play button) are not the view
        mask = ndimage.binary_opening(mask, structure=np.ones((3, 3)), iterations=2)
        ys, xs = np.nonzero(mask)
        if len(ys) < min_px:
            out[name] = (int(len(ys)), None, None)
            continue
        box = (int(ys.min()), int(ys.max()), int(xs.min()), int(xs.max()))
        room = (box[0] - top, bottom - box[1], box[2] - left, right_edge - box[3])
        out[name] = (int(len(ys)), box, room)
    return out


def assert_dice_inside(img, colours, right: int, what: str, margin: int = 3) -> dict:
    """Every die of ``colours`` (:func:`dice_in_view`) is found, and is inside the 3-D view by ``margin`` pixels."""
    seen = dice_in_view(img, colours, right)
    for name, (px, box, room) in seen.items():
        assert box is not None, f"{what}: die {name} not found ({px} px of its colour): {seen}"
        assert min(room) >= margin, f"{what}: die {name} is cut by the 3-D view's edge (room top, bottom, left, right: {room}): {seen}"
    return seen
