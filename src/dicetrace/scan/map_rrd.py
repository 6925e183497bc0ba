"""The scan map as a Rerun recording: outcome image, hover points, axes in slice coordinates, face legend.

A 2-D scan is drawn in its own slice coordinates with y up: everything lies
under ``/map``, whose transform mirrors y (Rerun's 2-D view points y down),
so the data keep their true coordinates (a hovered point shows ``(x, y)``,
not ``(x, -y)``).  Under it:

``/map/outcome``
    a grid scan's outcomes as one ``SegmentationImage`` (one byte a cell,
    pixel ``[j, i]`` = grid point ``(i, j)``), placed on the grid cells by
    its own transform; class ids are :data:`CLASS_IDS`.
``/map/cells``
    one point per IC at its slice coordinates with its class id: what the
    viewer shows on hover (position, "face 3"); for grids of at most
    :data:`MAX_LABELLED` cells, and for samples and point lists, also a
    label rounded to the grid's resolution (coordinates, face, steps).
``/map/axes``
    the frame, ticks and tick labels in slice coordinates, and the axis names.
``/map/legend``
    one swatch per outcome present, in the writeup's face colours.

The annotation context on ``/map`` names and colours each class id, so the
image, the points and the legend agree.  A 3-D slice is a ``Points3D``
scatter with the same classes.  ``/definition`` holds the scan definition.
A 400² map takes about 1.1 MB (it took 14.6 MB as a scatter with a 17-digit
label per point).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from dicetrace.ics import Grid
from dicetrace.scan.colours import OUTCOME_NAMES, OUTCOME_RGB
from dicetrace.scan.read import label_grid, read_scan, scan_definition
from dicetrace.sinks._common import destination, write_bytes
from dicetrace.sinks.rerun import encode_rrd

#: Class id of each outcome: faces 1..6 keep their number; 0 is cells not computed yet (transparent).
CLASS_IDS = {1: 1, 2: 2, 3: 3, 4: 4, 5: 5, 6: 6, 0: 7, -1: 8}
#: Grids of at most this many cells get a text label per point (beyond, the hover shows position and face).
MAX_LABELLED = 40_000
#: Colour of the frame, ticks and their labels.
AXIS_RGB = (200, 200, 200)
#: Background of the 2-D view: grey, so that face 6 (black) and the gaps of a sample show.
BACKGROUND_RGB = (72, 72, 72)


def class_ids(outcome) -> np.ndarray:
    """Class id of each outcome (-2, not computed yet: 0)."""
    table = np.zeros(9, dtype=np.uint16)  # index outcome + 2
    for o, c in CLASS_IDS.items():
        table[o + 2] = c
    return table[np.asarray(outcome, dtype=np.int64) + 2]


def class_label(o: int) -> str:
    return f"face {o}" if o > 0 else OUTCOME_NAMES[o]


def nice_ticks(lo: float, hi: float, n: int = 5) -> tuple[np.ndarray, list[str]]:
    """About ``n`` round tick values in [lo, hi] and their labels (as many decimals as the step needs)."""
    span = hi - lo
    if not span > 0:
        return np.array([lo]), [f"{lo:.6g}"]
    raw = span / n
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw * (1 - 1e-9))
    first = math.ceil(lo / step - 1e-9) * step
    ticks = first + step * np.arange(int(math.floor((hi - first) / step + 1e-9)) + 1)
    decimals = max(0, -math.floor(math.log10(step) + 1e-9)) + (1 if round(step / mag, 6) == 2.5 else 0)
    labels = [f"{t:.{decimals}f}" for t in ticks]
    return ticks, [lab[1:] if lab.startswith("-") and float(lab) == 0 else lab for lab in labels]  # no "-0.0"


def _decimals(step: float) -> int:
    """Decimals that tell two neighbouring grid points apart."""
    return max(0, 1 - math.floor(math.log10(step))) if step > 0 else 6


def point_labels(coords: np.ndarray, outcome, steps, steps_xy) -> list[str]:
    """Hover text of each point: its coordinates rounded to the grid's resolution, outcome and steps."""
    decs = [_decimals(s) for s in steps_xy]
    names = "xyz"[: coords.shape[1]]
    out = []
    for c, o, n in zip(coords.tolist(), np.asarray(outcome).tolist(), np.asarray(steps).tolist()):
        at = ", ".join(f"{a}={v:.{d}f}" for a, v, d in zip(names, c, decs))
        out.append(f"{at}: {class_label(int(o))}, {int(n)} steps")
    return out


def _annotation(rr):
    return rr.AnnotationContext([
        rr.AnnotationInfo(id=0, label="not computed yet", color=(0, 0, 0, 0)),  # transparent
        *(rr.AnnotationInfo(id=CLASS_IDS[o], label=class_label(o), color=OUTCOME_RGB[o]) for o in sorted(CLASS_IDS)),
    ])


def _log_axes(rec, rr, xlim, ylim) -> None:
    """Frame, ticks and tick labels of the box ``xlim`` × ``ylim`` (slice coordinates)."""
    (x0, x1), (y0, y1) = xlim, ylim
    L = 0.02 * max(x1 - x0, y1 - y0)
    xt, xl = nice_ticks(x0, x1)
    yt, yl = nice_ticks(y0, y1)
    strips = [[(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]]
    strips += [[(t, y0), (t, y0 - L)] for t in xt]
    strips += [[(x0, t), (x0 - L, t)] for t in yt]
    rec.log("/map/axes/lines", rr.LineStrips2D(strips, colors=AXIS_RGB, radii=rr.Radius.ui_points(0.75)), static=True)
    rec.log("/map/axes/x_ticks", rr.Points2D([(t, y0 - 2.5 * L) for t in xt], labels=xl, colors=AXIS_RGB,
                                             radii=rr.Radius.ui_points(0.1), show_labels=True), static=True)
    rec.log("/map/axes/y_ticks", rr.Points2D([(x0 - 2 * L, t + 0.5 * L) for t in yt], labels=yl, colors=AXIS_RGB,
                                             radii=rr.Radius.ui_points(0.1), show_labels=True), static=True)
    rec.log("/map/axes/names", rr.Points2D([(0.5 * (x0 + x1), y0 - 5 * L), (x0 - 5 * L, 0.5 * (y0 + y1))],
                                           labels=["x", "y"], colors=AXIS_RGB, radii=rr.Radius.ui_points(0.1),
                                           show_labels=True), static=True)


def legend_order(present) -> list[int]:
    """The outcomes the legend lists, top to bottom: the faces present, then undefined, then not settled."""
    return [o for o in (1, 2, 3, 4, 5, 6, 0, -1) if o in present]


def _log_legend(rec, rr, present, xlim, ylim) -> None:
    """One square swatch per outcome present, right of the map, each framed and named."""
    (x0, x1), (y0, y1) = xlim, ylim
    s = 0.05 * max(x1 - x0, y1 - y0)
    order = legend_order(present)
    n = len(order)
    left, bottom = x1 + 1.5 * s, y1 - s * (2 * n - 1)
    swatches = np.zeros((2 * n - 1, 1), dtype=np.uint8)  # row 0 at the bottom (y is mirrored); gaps are class 0
    for k, o in enumerate(order):
        swatches[2 * (n - 1 - k), 0] = CLASS_IDS[o]
    rec.log("/map/legend/swatches", rr.Transform3D(translation=[left, bottom, 0.0], scale=[s, s, 1.0]), static=True)
    rec.log("/map/legend/swatches", rr.SegmentationImage(swatches, draw_order=2.0), static=True)
    centers = [(left + s / 2, y1 - s * (2 * k + 0.5)) for k in range(n)]
    rec.log("/map/legend/frames", rr.Boxes2D(centers=centers, half_sizes=[(s / 2, s / 2)] * n, colors=AXIS_RGB,
                                             radii=rr.Radius.ui_points(0.5), draw_order=3.0), static=True)
    names = [class_label(o) for o in order]
    # a label is drawn centred just below its point: move each right of its swatch by about half its width
    # (7 px a character at the default zoom, where s is about 25 px), and up
    anchors = [(cx + 0.8 * s + 0.14 * s * len(t), cy + 0.45 * s) for (cx, cy), t in zip(centers, names)]
    rec.log("/map/legend/names", rr.Points2D(anchors, labels=names, colors=AXIS_RGB, radii=rr.Radius.ui_points(0.1),
                                             show_labels=True), static=True)


def log_scan_map(rec, folder) -> None:
    """Log a scan folder's map into ``rec`` (see the module docstring)."""
    import rerun as rr  # rerun is slow to import: only when a map is written

    defn = scan_definition(folder)
    space = defn.space
    nd = space.ndim
    cols = ["x", "y", "z"][:nd]
    df = read_scan(folder, columns=[*cols, "outcome", "steps"])
    outcome = df["outcome"].to_numpy().astype(np.int64)
    coords = df[cols].to_numpy(dtype=np.float64) if nd > 1 else np.stack([df["x"].to_numpy(), np.zeros(len(df))], 1)
    present = set(np.unique(outcome).tolist())
    rec.log("/map", _annotation(rr), static=True)
    grid = isinstance(space, Grid)
    if grid:
        steps_xy = [(hi - lo) / max(n - 1, 1) for (lo, hi), n in zip(space.window, space.res)]
    else:
        ext = np.ptp(coords, axis=0) if len(coords) else np.ones(coords.shape[1])
        steps_xy = list(np.maximum(ext, 1e-12) / max(len(coords), 1) ** (1 / coords.shape[1]))
    labelled = not grid or len(df) <= MAX_LABELLED
    labels = point_labels(coords[:, :nd] if nd > 1 else coords[:, :1], outcome, df["steps"].to_numpy(),
                          steps_xy) if labelled else None
    ids = class_ids(outcome)
    if nd == 3:
        radius = 0.5 * min(s for s in steps_xy if s > 0) if any(s > 0 for s in steps_xy) else 0.5
        rec.log("/map/cells", rr.Points3D(coords, class_ids=ids, radii=radius, labels=labels, show_labels=False),
                static=True)
        rec.log("/map", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        return
    rec.log("/map", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)  # y up on screen, true coordinates
    hx = steps_xy[0] if steps_xy[0] > 0 else 1.0
    hy = (steps_xy[1] if len(steps_xy) > 1 and steps_xy[1] > 0 else hx)
    if grid:
        (xa, xb) = space.window[0]
        (ya, yb) = space.window[1] if nd > 1 else (0.0, 0.0)
        xlim = (xa - hx / 2, xb + hx / 2)
        ylim = (ya - hy / 2, yb + hy / 2)
        cells = label_grid(folder)
        cells = cells.reshape(cells.shape[0], -1)  # [i, j]; a 1-D grid is one row
        image = class_ids(cells.T).astype(np.uint8)  # pixel [j, i]
        rec.log("/map/outcome", rr.Transform3D(translation=[xlim[0], ylim[0], 0.0], scale=[hx, hy, 1.0]),
                static=True)
        rec.log("/map/outcome", rr.SegmentationImage(image, draw_order=0.0), static=True)
        radius = 0.5 * min(hx, hy)
    else:
        lo, hi = coords.min(axis=0), coords.max(axis=0)
        pad = 0.5 * np.array([hx, hy])
        xlim, ylim = (lo[0] - pad[0], hi[0] + pad[0]), (lo[1] - pad[1], hi[1] + pad[1])
        radius = 0.5 * min(hx, hy)
    # over the image, in the same colours (the viewer draws no transparent point): they carry the hover
    rec.log("/map/cells", rr.Points2D(coords.astype(np.float32), class_ids=ids, radii=radius, labels=labels,
                                      show_labels=False, draw_order=1.0), static=True)
    _log_axes(rec, rr, xlim, ylim)
    _log_legend(rec, rr, present, xlim, ylim)


def write_scan_rrd(folder, path, *, staging=None) -> Path:
    """Write a scan folder's map (see the module docstring) to ``path``: a ``.rrd`` file (atomically), a device
    or FIFO, or ``"-"``; checked before any work.  ``staging``: put it in place with the other outputs."""
    import rerun.blueprint as rrb  # rerun is slow to import: only when a map is written

    dest = destination(path, what="scan map", suffix=".rrd")
    defn = scan_definition(folder)
    stem = Path(dest.given).stem or "scan"

    def log(rec) -> None:
        import rerun as rr  # rerun is slow to import: only when a map is written

        rec.send_recording_name(f"scan {stem}")
        log_scan_map(rec, folder)
        rec.log("/definition", rr.TextDocument(_definition_markdown(defn), media_type="text/markdown"), static=True)

    if defn.space.ndim <= 2:
        view = rrb.Spatial2DView(origin="/", contents="/map/**", name="outcome map", background=BACKGROUND_RGB)
    else:
        view = rrb.Spatial3DView(origin="/map", name="outcome map")
    data = encode_rrd(log, rrb.Blueprint(view, collapse_panels=True), application_id="dicetrace-scan")
    if staging is None:
        write_bytes(dest, data)
    else:
        tmp = staging.path(dest)
        try:
            tmp.write_bytes(data)
        except OSError as e:
            raise staging.fail(dest, e) from None
    return Path(dest.given)


def _definition_markdown(defn) -> str:
    return "# dicetrace scan\n\n```json\n" + json.dumps(defn.to_dict(), indent=1) + "\n```\n"
