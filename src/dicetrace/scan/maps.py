"""The outcome map of a scan as a PNG (the Rerun map is :mod:`~dicetrace.scan.map_rrd`, the colours
:mod:`~dicetrace.scan.colours`).

matplotlib is imported inside the function (heavy, and only a map needs it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dicetrace.scan.colours import OUTCOME_NAMES, OUTCOME_RGB
from dicetrace.scan.read import grid_axes, label_grid, scan_definition
from dicetrace.sinks._common import destination, staged
from dicetrace.windows import WINDOWS


def outcome_png(folder, path, *, k: int = 0, title: str | None = None, dpi: int = 150, staging=None) -> Path:
    """Draw a 2-D grid scan's outcome map (or z-level ``k`` of a 3-D one) into ``path``.

    ``path``: a ``.png`` file (written atomically), a character device or
    FIFO, or ``"-"`` (standard output); see
    :func:`dicetrace.sinks._common.destination`.  Checked before any work.
    ``staging``: a :class:`~dicetrace.sinks._common.Staging` to stage the
    file in (put in place by its ``commit``, with the other outputs).
    """
    dest = destination(path, what="outcome map", suffix=".png")
    import matplotlib  # heavy: imported only when a map is drawn

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

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
