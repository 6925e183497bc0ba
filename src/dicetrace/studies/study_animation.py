"""Study i (animation): the third slice axis as time (writeup 6.1).

The writeup proposes replacing its unreadable 3-D scatter by "a video of a
2-D scatter, where the third component of ic changes with time". This
animates the seed 3-D slice over the red-sea window (the program's own 3-D
scatter: x ∈ [1, 2], y ∈ [3.5, 4.5]; the program took z ∈ [0, 1], here z ∈ [0, 0.25]
so that consecutive frames, 0.01 apart, stay comparable) as a GIF, plus a strip of
four frames as a PNG for the report.
"""

from __future__ import annotations

import numpy as np

from dicetrace.analysis.plot import animate_slices, plot_outcome_map
from dicetrace.studies.context import MAX_FIG_BYTES, Computed, Context, Output, window_ranges
from dicetrace.studies.outputs import written

NAME = "animation"
Z_RANGE = (0.0, 0.25)
GIF = "i_redsea_z.gif"
#: Frames along z (full run, --quick).
NZ = (26, 6)


def compute(ctx: Context) -> Computed:
    res = ctx.res(161, 41)
    nz = ctx.pick(*NZ)
    window = tuple(window_ranges("red-sea")) + (Z_RANGE,)
    s = ctx.sample(window, (res, res, nz), slice_spec="seed3")
    g = s.labels
    results = {
        # how fast the picture changes with z: fraction of nodes whose outcome differs between frames
        "frame_change_fraction": [float(np.mean(g[:, :, q] != g[:, :, q + 1])) for q in range(nz - 1)],
        "red_fraction": [float(np.mean(g[:, :, q] == 3)) for q in range(nz)],
        "z": s.axes[2],
        "res": [res, res, nz],
    }
    return Computed(results, {"grid": g})


def render(c: Computed, out: Output) -> None:
    import matplotlib  # matplotlib is slow to import: only when drawing
    import matplotlib.pyplot as plt

    g, zs = c.plot["grid"], np.asarray(c.results["z"])
    res, _, nz = c.results["res"]
    path = out.fig_dir / GIF
    ext = list(window_ranges("red-sea"))
    for dpi in (60, 50, 40, 32):
        with matplotlib.rc_context({"figure.dpi": dpi}), written(path, "figure") as tmp:
            plt.close(animate_slices(g, tmp, extent=ext, z_values=zs, fps=4, title="red sea, z = {z:.2f}"))
        if path.stat().st_size <= MAX_FIG_BYTES:
            break
    out.add_file(f"figures/{GIF}", "i_gif", caption=f"The red-sea window of the seed 3-D slice, z from "
                 f"{Z_RANGE[0]:g} to {Z_RANGE[1]:g} as time ({res}² per frame, {nz} frames).")
    picks = np.linspace(0, nz - 1, 4).round().astype(int)
    fig, axes = plt.subplots(1, 4, figsize=(14, 3.6))
    for ax, kz in zip(axes, picks):
        plot_outcome_map(g[:, :, kz], extent=ext, ax=ax, legend=False, title=f"z = {zs[kz]:.2f}")
    fig.tight_layout()
    out.save_fig(fig, "i_redsea_frames", caption="Four frames of the animation.")
