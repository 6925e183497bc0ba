"""Study i: the third slice axis as time (writeup 6.1).

The writeup proposes replacing its unreadable 3-D scatter by "a video of a
2-D scatter, where the third component of ic changes with time". This
animates the seed 3-D slice over the red-sea window (the program's own 3-D
scatter: x ∈ [1, 2], y ∈ [3.5, 4.5]; the program took z ∈ [0, 1], here z ∈ [0, 0.25]
so that consecutive frames, 0.01 apart, stay comparable) as a GIF, plus a strip of
four frames as a PNG for the report.

    python analysis/i_animation.py [--quick] [--res N] [--out DIR]
"""

from __future__ import annotations

import sys

import numpy as np

import _common as C

NAME = "animation"
WINDOW = ((1.0, 2.0), (3.5, 4.5), (0.0, 0.25))


def main(argv=None) -> dict:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    st = C.Study(NAME, args)
    import matplotlib
    import matplotlib.pyplot as plt

    from dicetrace.analysis.plot import animate_slices, plot_outcome_map

    res = st.res(161, 41)
    nz = st.pick(26, 6)
    s = st.sample(WINDOW, (res, res, nz), slice_spec="seed3")
    g = s.labels
    zs = s.axes[2]
    path = st.fig_dir / "i_redsea_z.gif"
    ext = [WINDOW[0], WINDOW[1]]
    for dpi in (60, 50, 40, 32):
        with matplotlib.rc_context({"figure.dpi": dpi}):
            fig = animate_slices(g, path, extent=ext, z_values=zs, fps=4, title="red sea, z = {z:.2f}")
            plt.close(fig)
        if path.stat().st_size <= C.MAX_FIG_BYTES:
            break
    st.add_file(f"figures/{path.name}", "i_gif", caption=f"The red-sea window of the seed 3-D slice, z from 0 to 0.25 "
                f"as time ({res}² per frame, {nz} frames).")
    # four frames side by side
    picks = np.linspace(0, nz - 1, 4).round().astype(int)
    fig, axes = plt.subplots(1, 4, figsize=(14, 3.6))
    for ax, kz in zip(axes, picks):
        plot_outcome_map(g[:, :, kz], extent=ext, ax=ax, legend=False, title=f"z = {zs[kz]:.2f}")
    fig.tight_layout()
    st.save_fig(fig, "i_redsea_frames", caption="Four frames of the animation.")
    # how fast the picture changes with z: fraction of nodes whose outcome differs between frames
    change = [float(np.mean(g[:, :, q] != g[:, :, q + 1])) for q in range(nz - 1)]
    red = [float(np.mean(g[:, :, q] == 3)) for q in range(nz)]
    st.results["frame_change_fraction"] = change
    st.results["red_fraction"] = red
    st.results["z"] = zs
    st.results["res"] = [res, res, nz]
    st.results["gif_bytes"] = path.stat().st_size
    st.write()
    return st.results


if __name__ == "__main__":
    main(sys.argv[1:])
