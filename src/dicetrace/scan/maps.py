"""Pictures of a scan: the outcome map as a PNG and as an interactive Rerun scatter.

matplotlib and rerun are imported inside the functions.  Colours are the
writeup's: face 1 blue, 2 green, 3 red, 4 magenta, 5 yellow, 6 black;
0 (undefined) grey, -1 (did not settle) white.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dicetrace.sinks._common import destination, staged, write_bytes

#: RGB (0-255) of each outcome label -1..6.
OUTCOME_RGB: dict[int, tuple[int, int, int]] = {
    -1: (255, 255, 255),
    0: (128, 128, 128),
    1: (0, 0, 255),
    2: (0, 128, 0),
    3: (255, 0, 0),
    4: (255, 0, 255),
    5: (255, 255, 0),
    6: (0, 0, 0),
}
OUTCOME_NAMES = {-1: "did not settle", 0: "undefined", 1: "1", 2: "2", 3: "3", 4: "4", 5: "5", 6: "6"}


def _rgb_table() -> np.ndarray:
    t = np.zeros((8, 3), dtype=np.uint8)
    for k, rgb in OUTCOME_RGB.items():
        t[k + 1] = rgb
    return t


def outcome_png(folder, path, *, k: int = 0, title: str | None = None, dpi: int = 150, staging=None) -> Path:
    """Draw a 2-D grid scan's outcome map (or z-level ``k`` of a 3-D one) into ``path``.

    ``path``: a ``.png`` file (written atomically), a character device or
    FIFO, or ``"-"`` (standard output); see
    :func:`dicetrace.sinks._common.destination`.  Checked before any work.
    ``staging``: a :class:`~dicetrace.sinks._common.Staging` to stage the
    file in (put in place by its ``commit``, with the other outputs).
    """
    dest = destination(path, what="outcome map", suffix=".png")
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    from dicetrace.scan.read import grid_axes, label_grid, scan_definition

    defn = scan_definition(folder)
    grid = label_grid(folder)
    axes = grid_axes(folder)
    if grid.ndim == 3:
        grid = grid[:, :, k]
    order = [-1, 0, 1, 2, 3, 4, 5, 6]
    cmap = ListedColormap([np.array(OUTCOME_RGB[o]) / 255 for o in order]).with_extremes(
        under=(0.85, 0.85, 0.85)  # cells not computed yet
    )
    norm = BoundaryNorm(np.arange(-1.5, 7.0, 1.0), cmap.N)
    xs, ys = axes[0], axes[1]
    hx = (xs[-1] - xs[0]) / max(len(xs) - 1, 1) if len(xs) > 1 else 1.0
    hy = (ys[-1] - ys[0]) / max(len(ys) - 1, 1) if len(ys) > 1 else 1.0
    fig, ax = plt.subplots(figsize=(6.4, 5.4))
    ax.imshow(grid.T, origin="lower", cmap=cmap, norm=norm, interpolation="nearest", aspect="auto",
              extent=(xs[0] - hx / 2, xs[-1] + hx / 2, ys[0] - hy / 2, ys[-1] + hy / 2))
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    from dicetrace.ics import WINDOWS

    sl = defn.space.slice.name
    names = [n for n, w in WINDOWS.items() if tuple(w) == tuple(defn.space.window[:2])]
    where = f"the {names[0]} window of the {sl} slice" if names else f"the {sl} slice"
    ax.set_title(title or f"Outcome on {where}, {grid.shape[0]}×{grid.shape[1]} ({defn.config.preset.name} preset)")
    present = set(np.unique(grid).tolist())
    ax.legend(handles=[Patch(facecolor=np.array(OUTCOME_RGB[o]) / 255, edgecolor="0.3", label=OUTCOME_NAMES[o])
                       for o in order if o in present],
              loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False, title="face up")
    fig.tight_layout()
    try:
        if staging is None:
            with staged(dest) as tmp:
                fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format="png")
        else:
            tmp = staging.path(dest)
            try:
                fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format="png")
            except OSError as e:
                raise staging.fail(dest, e) from None
    finally:
        plt.close(fig)
    return Path(dest.given)


def scan_labels(df) -> list[str]:
    """Hover text of each scanned IC: coordinates, outcome, steps and the IC itself."""
    cols = [c for c in ("x", "y", "z") if c in df and df[c].notna().any()]
    out = []
    it = zip(*(df[c].to_numpy() for c in cols), df["outcome"].to_numpy(), df["steps"].to_numpy(),
             *(df[c].to_numpy() for c in ("vx", "vy", "vz", "Lx", "Ly", "Lz")))
    for row in it:
        c = row[: len(cols)]
        o, n = row[len(cols)], row[len(cols) + 1]
        ic = row[len(cols) + 2 :]
        at = ", ".join(f"{name}={float(v)!r}" for name, v in zip(cols, c))
        out.append(
            f"{at}: face {int(o)}, {int(n)} steps | U=({float(ic[0])!r}, {float(ic[1])!r}, {float(ic[2])!r}) "
            f"L=({float(ic[3])!r}, {float(ic[4])!r}, {float(ic[5])!r})"
        )
    return out


def write_scan_rrd(folder, path, *, labels: bool = True, staging=None) -> Path:
    """The scan as a Rerun recording: one point per IC, coloured by outcome.

    2-D slices are logged as ``Points2D`` at (x, −y) (the 2-D view's y axis
    points down: negating keeps y up on screen), 3-D slices as ``Points3D``.
    Each point's label holds its slice coordinates, outcome, steps and the
    full IC (exact ``repr`` floats: ``dicetrace record --ic ...`` or
    ``--scan DIR --at X,Y`` reproduces it).  Class ids are ``outcome + 1``
    with an annotation context naming the faces.  ``path`` as in
    :func:`outcome_png` (``.rrd``), checked before any work; ``staging`` too.
    """
    import rerun as rr
    import rerun.blueprint as rrb

    from dicetrace.ics import Grid
    from dicetrace.scan.read import read_scan, scan_definition
    from dicetrace.sinks.rerun import encode_rrd

    dest = destination(path, what="scan map", suffix=".rrd")
    defn = scan_definition(folder)
    df = read_scan(folder, columns=["x", "y", "z", "outcome", "steps", "vx", "vy", "vz", "Lx", "Ly", "Lz"])
    nd = defn.space.ndim
    outcome = df["outcome"].to_numpy().astype(np.int64)
    colors = _rgb_table()[outcome + 1]
    if isinstance(defn.space, Grid):
        spans = [(hi - lo) / max(n - 1, 1) for (lo, hi), n in zip(defn.space.window, defn.space.res)]
        radius = 0.5 * min(s for s in spans if s > 0) if any(s > 0 for s in spans) else 0.5
    else:  # half the mean spacing of the points in their bounding box
        pts = df[["x", "y", "z"][:nd]].to_numpy()
        ext = np.maximum(pts.max(axis=0) - pts.min(axis=0), 1e-12) if len(pts) else np.ones(nd)
        radius = 0.5 * float(np.prod(ext) / max(len(pts), 1)) ** (1.0 / nd)
    view = (rrb.Spatial2DView(origin="/scan", name="outcome map") if nd <= 2
            else rrb.Spatial3DView(origin="/scan", name="outcome map"))
    stem = Path(dest.given).stem or "scan"

    def log(rec) -> None:
        rec.send_recording_name(f"scan {stem}")
        rec.log(
            "/scan",
            rr.AnnotationContext([
                rr.AnnotationInfo(id=o + 1, label=f"face {OUTCOME_NAMES[o]}" if o > 0 else OUTCOME_NAMES[o],
                                  color=OUTCOME_RGB[o])
                for o in OUTCOME_RGB
            ]),
            static=True,
        )
        lab = scan_labels(df) if labels else None
        x = df["x"].to_numpy()
        y = df["y"].to_numpy() if nd >= 2 else np.zeros(len(df))
        if nd <= 2:
            arch = rr.Points2D(np.stack([x, -y], axis=1), colors=colors, radii=radius, labels=lab,
                               class_ids=outcome + 1, show_labels=False)
        else:
            arch = rr.Points3D(np.stack([x, y, df["z"].to_numpy()], axis=1), colors=colors, radii=radius,
                               labels=lab, class_ids=outcome + 1, show_labels=False)
        rec.log("/scan/outcome", arch, static=True)
        rec.log("/scan/definition", rr.TextDocument(_definition_markdown(defn), media_type="text/markdown"),
                static=True)

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
    import json

    return "# dicetrace scan\n\n```json\n" + json.dumps(defn.to_dict(), indent=1) + "\n```\n"
