"""Study a (cells): the cell structure of the home window and the zoom ladder (writeup 4.1).

Outcome maps of home [0, .1]², zoom-out [0, 1]², more-out [0, 10]² and
most-out [0, 100]² on the seed slice, in the writeup's face colours, with
cell statistics (connected regions of one outcome, face connectivity):
number of cells, size distribution, how many a coarser grid sees, and the
basin fractions with 95 % Wilson intervals and block errors.
"""

from __future__ import annotations

import numpy as np

from dicetrace.analysis import basins_fractions_table
from dicetrace.analysis.cells import block_fraction_stderr, cell_stats
from dicetrace.analysis.plot import plot_outcome_map, plot_zoom_series
from dicetrace.studies.context import Computed, Context, Output
from dicetrace.studies.text import md_table

NAME = "cells"
WINDOWS = ("home", "zoom-out", "more-out", "most-out")


def compute(ctx: Context) -> Computed:
    res = ctx.res(401, 41)
    # coarser grids are subsamples of the main one (every 2nd / 4th node): same nominal points
    steps = [1, 2, 4] if (res - 1) % 4 == 0 else [1]
    out, samples, sizes = {}, {}, {}
    for w in WINDOWS:
        s = ctx.sample(w, res)
        g = s.labels
        samples[w] = s
        stats = cell_stats(g)
        sizes[w] = stats.pop("sizes")
        by_res = []
        for k in steps:
            sub = g[::k, ::k]
            cs = cell_stats(sub)
            by_res.append({"res": sub.shape[0], "spacing": (s.window[0][1] - s.window[0][0]) / (sub.shape[0] - 1),
                           "n_cells": cs["n_cells"], "cells_per_1000_nodes": cs["cells_per_1000_nodes"],
                           "frac_nodes_in_singletons": cs["frac_nodes_in_singletons"],
                           "largest_cell_frac": cs["largest_cell_frac"]})
        fr = [{"label": int(r["label"]), "count": int(r["count"]), "fraction": float(r["fraction"]),
               "ci_low": float(r["ci_low"]), "ci_high": float(r["ci_high"]),
               "block_stderr": block_fraction_stderr(g, int(r["label"]))}
              for _, r in basins_fractions_table(g).iterrows()]
        # largest deviation from the uniform 1/6 in units of the block stderr
        dev = max(abs(f["fraction"] - 1 / 6) / max(f["block_stderr"], 1e-12) for f in fr if f["label"] > 0)
        out[w] = {
            "window": s.window, "res": g.shape[0], "spacing": s.spacing[0],
            "cells": stats, "cells_by_res": by_res, "fractions": fr,
            "max_dev_from_uniform_in_block_stderr": dev,
            "n_undefined": int((g == 0).sum()), "n_unsettled": int((g == -1).sum()),
            "mean_settle_s": float(s.t_settle_s.mean()),
            "max_settle_s": float(s.t_settle_s.max()),
        }
        ctx.log(f"{w}: {stats['n_cells']} cells, largest {stats['largest_cell_frac']:.3f}")
    return Computed({"windows": out, "res": res}, {"samples": samples, "sizes": sizes})


def render(c: Computed, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    win, res = c.results["windows"], c.results["res"]
    samples = c.plot["samples"]
    for w in WINDOWS:
        s = samples[w]
        fig, ax = plt.subplots(figsize=(5.6, 4.8))
        plot_outcome_map(s.labels, extent=s.extent, ax=ax, title=f"{w} window, {s.labels.shape[0]}² throws")
        out.save_fig(fig, f"a_map_{w}", caption=f"Outcome map of the {w} window {s.window} ({s.labels.shape[0]}² grid).")
    # the ladder, outermost first, each window framed in the one before
    order = list(reversed(WINDOWS))
    fig = plot_zoom_series([samples[w].labels for w in order], [samples[w].extent for w in order],
                           titles=list(order), ncols=4)
    out.save_fig(fig, "a_zoom_ladder", caption="The zoom ladder: most-out → more-out → zoom-out → home; "
                 "each panel's white box is the next window (boxes smaller than a pixel are invisible).")
    fig, ax = plt.subplots(figsize=(5.6, 4.2))
    for w in WINDOWS:
        sz = np.sort(c.plot["sizes"][w])
        n = samples[w].labels.size
        # area-weighted CCDF: fraction of the window's nodes lying in cells at least this large
        ax.loglog(sz / n, np.cumsum(sz[::-1])[::-1] / n, drawstyle="steps-post", label=w)
    out.save_plot(fig, ax, "a_cell_sizes", xlabel="cell size (fraction of the window)",
                  ylabel="fraction of the window in cells ≥ this size", title=f"Cell sizes ({res}² grids, face connectivity)",
                  caption="Area-weighted cell-size distribution of each window.", legend=True)

    rows = [{"window": w, "res": win[w]["res"], "n_cells": cs["n_cells"], "per1000": cs["cells_per_1000_nodes"],
             "single": cs["frac_nodes_in_singletons"], "ge100": cs["n_cells_ge_100"],
             "largest": cs["largest_cell_frac"], "largest_label": cs["largest_cell_label"],
             "median": cs["median_size"]} for w in WINDOWS for cs in (win[w]["cells"],)]
    out.tables["cells"] = md_table(rows, [
        ("window", "window", ""), ("res", "grid", "d"), ("n_cells", "cells", "d"),
        ("per1000", "cells / 1000 nodes", ".1f"), ("single", "nodes in 1-node cells", ".3f"),
        ("ge100", "cells ≥ 100 nodes", "d"), ("largest", "largest cell (fraction)", ".4f"),
        ("largest_label", "its face", "d"), ("median", "median cell (nodes)", ".0f")])
    rrows = [{"window": w, "res": b["res"], "spacing": b["spacing"], "n_cells": b["n_cells"],
              "per1000": b["cells_per_1000_nodes"], "single": b["frac_nodes_in_singletons"]}
             for w in WINDOWS for b in win[w]["cells_by_res"]]
    out.tables["cells_by_res"] = md_table(rrows, [
        ("window", "window", ""), ("res", "grid", "d"), ("spacing", "spacing", ".3g"),
        ("n_cells", "cells", "d"), ("per1000", "cells / 1000 nodes", ".1f"),
        ("single", "nodes in 1-node cells", ".3f")])
    frows = []
    for w in WINDOWS:
        r = {"window": w, "dev": win[w]["max_dev_from_uniform_in_block_stderr"]}
        for f in win[w]["fractions"]:
            r[str(f["label"])] = f"{f['fraction']:.4f} ± {f['block_stderr']:.4f}"
        frows.append(r)
    out.tables["fractions"] = md_table(frows, [("window", "window", "")] + [
        (str(k), f"face {k}", "") for k in range(1, 7)] + [("dev", "max |f − 1/6| / stderr", ".1f")])
