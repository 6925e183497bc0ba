"""The real Rerun viewer renders a recording: screenshot under Xvfb (software Vulkan), ~15-20 s.

Skipped where ``xvfb-run`` or the ``rerun`` CLI is missing.  The recording's
blueprint puts the viewer at the last step ("following"), so the die lies on
the ground with its outcome face up: for the seed slice at (1.65, 3.9) that
is face 3, red in the writeup's colours.  The face numbers are read back from
the screenshot by OCR (Debian's ``tesseract``; that check is skipped where it
is missing).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.viewer, pytest.mark.slow]

RERUN_CLI = Path(sys.executable).parent / "rerun"
XVFB = shutil.which("xvfb-run")
RERUN = str(RERUN_CLI) if RERUN_CLI.exists() else shutil.which("rerun")
TESSERACT = shutil.which("tesseract")


def _ocr_digit(img: np.ndarray) -> str:
    """The digit 1..6 that tesseract reads in a grey image (dark glyph on white), '' if none."""
    from PIL import Image

    with tempfile.TemporaryDirectory() as d:
        Image.fromarray(img).save(Path(d) / "glyph.png")
        res = subprocess.run([TESSERACT, str(Path(d) / "glyph.png"), "-", "--psm", "10", "-c",
                              "tessedit_char_whitelist=123456"], capture_output=True, text=True, timeout=30)
    return res.stdout.strip()


def face_numbers_read(view: np.ndarray, colors) -> dict[int, list[str]]:
    """Face value → what OCR reads in each glyph-sized blob of exactly that face's colour.

    The viewer draws each face's label in the face's colour over a dark box.
    For face k the image is turned into its distance from face k's colour
    (the glyph black, everything else white), each glyph-sized connected blob
    of near-exact pixels is cut out with a margin, scaled up 3x and read as
    one character.
    """
    from PIL import Image
    from scipy import ndimage

    out = {}
    for k, color in enumerate(np.asarray(colors, dtype=int), start=1):
        dist = np.abs(view - color).sum(axis=-1)
        lab, _ = ndimage.label(dist <= 24, structure=np.ones((3, 3)))
        reads = []
        for sl in ndimage.find_objects(lab):
            hh, ww = sl[0].stop - sl[0].start, sl[1].stop - sl[1].start
            if not (12 <= hh <= 60 and 2 <= ww <= 45 and hh >= 0.8 * ww):  # a glyph of the label font (2x scale)
                continue
            y0, x0 = max(sl[0].start - 10, 0), max(sl[1].start - 10, 0)
            sub = np.clip(dist[y0 : sl[0].stop + 10, x0 : sl[1].stop + 10] * 2.5, 0, 255).astype(np.uint8)
            big = Image.fromarray(sub).resize((3 * sub.shape[1], 3 * sub.shape[0]), Image.BICUBIC)
            reads.append(_ocr_digit(np.asarray(big)))
        out[k] = reads
    return out


def faces_towards(roll, eye) -> list[int]:
    """Face values whose outward normal points towards the camera at ``eye``, at the throw's last state."""
    from dicetrace.sinks.rerun import FACE_NODES

    tr = roll.trace
    last = int(np.flatnonzero(tr.written)[-1])
    cm, off = tr.cm_pos[last], tr.node_offsets[last]
    centres = cm + off[FACE_NODES].mean(axis=1)  # (6, 3)
    normals = centres - cm
    return [f + 1 for f in range(6) if float(normals[f] @ (np.asarray(eye) - centres[f])) > 0]


@pytest.mark.skipif(XVFB is None, reason="xvfb-run not on PATH")
@pytest.mark.skipif(RERUN is None, reason="rerun CLI not installed")
def test_viewer_screenshot_shows_the_die_on_the_ground(tmp_path):
    from PIL import Image

    from dicetrace.ics import seed_slice
    from dicetrace.simulate import Record, simulate
    from dicetrace.sinks.rerun import FACE_COLORS, GROUND_COLOR, _eye_for, write_rrd

    roll = simulate(seed_slice(1.65, 3.9), record=Record(states=True, energy=True))
    assert roll.outcome == 3
    rrd = write_rrd(roll, tmp_path / "throw.rrd")
    png = tmp_path / "shot.png"
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path)}
    cmd = [XVFB, "-a", "-s", "-screen 0 1400x900x24", RERUN, str(rrd), "--new", "--screenshot-to", str(png),
           "--window-size", "1400x900"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    assert png.exists() and png.stat().st_size > 10_000

    im = np.asarray(Image.open(png).convert("RGB")).astype(int)
    h, w, _ = im.shape
    assert w >= 1400 and h >= 900
    # not blank: contrast and many colours
    assert im.std() > 30
    assert len(np.unique(im.reshape(-1, 3) @ np.array([65536, 256, 1]))) > 500

    # the 3-D view is the left ~58 % of the window (blueprint column shares 3:2)
    view = im[int(0.05 * h) : int(0.95 * h), : int(0.55 * w)]
    r, g, b = view[..., 0], view[..., 1], view[..., 2]
    npx = r.size
    ground = (np.abs(view - np.array(GROUND_COLOR)).sum(axis=-1) <= 12).sum()
    assert ground > 0.05 * npx, "ground plane not visible"
    red_face = ((r > 150) & (g < 80) & (b < 80)).sum()  # face 3 (red) is up at rest
    assert red_face > 0.0005 * npx, "the die's red face is not visible"
    trail = ((r > 200) & (g > 100) & (g < 190) & (b < 70)).sum()  # orange centre-of-mass path
    assert trail > 0.0005 * npx, "centre-of-mass path not visible"
    # the right column (plots, contact log) uses the viewer's dark theme
    panels = im[int(0.1 * h) : int(0.9 * h), int(0.65 * w) :]
    assert (panels.sum(axis=-1) < 150).mean() > 0.3

    # the face numbers: each face turned towards the camera has its number, in its colour, read by OCR
    if TESSERACT is None:
        pytest.skip("tesseract not on PATH: the face numbers were not read (apt-get install tesseract-ocr)")
    eye = np.asarray(_eye_for(roll.trace.cm_pos, float(roll.config.preset.half_side_cm)).position.as_arrow_array()
                     .to_pylist()[0])
    facing = faces_towards(roll, eye)
    assert 3 in facing and 4 not in facing and 2 <= len(facing) <= 3, facing
    read = face_numbers_read(im[int(0.07 * h) : int(0.95 * h), : int(0.55 * w)], FACE_COLORS)
    missing = [k for k in facing if str(k) not in read[k]]
    assert not missing, f"face numbers {missing} not read on the die (OCR read, by face colour: {read})"


@pytest.mark.skipif(XVFB is None, reason="xvfb-run not on PATH")
@pytest.mark.skipif(RERUN is None, reason="rerun CLI not installed")
def test_viewer_screenshot_shows_the_compare_view(tmp_path):
    """``record --nudge``: both dice in their colours in the 3-D view, the log10 divergence curve in the plot."""
    from PIL import Image

    from dicetrace.ics import seed_slice
    from dicetrace.simulate import Record, simulate
    from dicetrace.sinks.rerun_compare import encode_compare_rrd, throw_color

    a = simulate(seed_slice(1.65, 3.9), record=Record(states=True, energy=True))
    b = simulate(a.ic * (1 + 1e-6), record=Record(states=True, energy=True))
    rrd = tmp_path / "compare.rrd"
    rrd.write_bytes(encode_compare_rrd([a, b], ["throw 0", "nudged"]))
    png = tmp_path / "shot.png"
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path)}
    cmd = [XVFB, "-a", "-s", "-screen 0 1400x900x24", RERUN, str(rrd), "--new", "--screenshot-to", str(png),
           "--window-size", "1400x900"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    im = np.asarray(Image.open(png).convert("RGB")).astype(int)
    h, w, _ = im.shape
    Image.fromarray(im.astype(np.uint8)).save(tmp_path / "copy.png")

    def near(region, color, tol=60):
        return int((np.abs(region - np.array(color)).sum(axis=-1) <= tol).sum())

    view = im[int(0.05 * h) : int(0.95 * h), : int(0.55 * w)]
    npx = view.shape[0] * view.shape[1]
    for k in (0, 1):  # each die, shaded, in its own colour
        assert near(view, throw_color(k)) > 0.0003 * npx, f"throw {k}'s die is not visible"
    plot = im[int(0.05 * h) : int(0.6 * h), int(0.62 * w) :]
    assert near(plot, throw_color(1), tol=40) > 200, "the divergence curve (throw 1's colour) is not drawn"
