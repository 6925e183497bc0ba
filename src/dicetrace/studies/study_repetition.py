"""Study c (repetition): period vectors, and one cell or many? (writeup 5.1)

The writeup saw "a periodic pattern" in a zoomed-out window and asked
whether the repeated regions are different cells or 2-D slices of one 6-D
cell. Here:

1. ``find_periods`` on the outcome grids of zoom-out and more-out (does the
   *outcome* pattern repeat?), and on a label-agnostic *texture*: the local
   density of cell borders (Gaussian-smoothed boundary mask, thresholded at
   its median), which is what the eye reads as "a pattern".
2. A 3-D stack of the seed 3-D slice (z adds (4.5669, 3.1618, 0.4877) to L
   and (1.3925, 2.7344, 4.7875) to U) over zoom-out and over red sea, with
   equal spacing on all three axes: ``periodic_cells_connected`` for the
   period vectors found, and ``slice_cell_components`` — how many 2-D cells
   of the z = 0 slice join other 2-D cells through the third dimension.
"""

from __future__ import annotations


import numpy as np

from dicetrace.analysis import find_periods, label_autocorrelation, label_cells, slice_cell_components
from dicetrace.analysis.cells import slice_joins
from dicetrace.analysis.plot import plot_outcome_map
from dicetrace.analysis.repetition import off_centre_max, period_overlaps, periods_rows, stripe_spacing, texture_labels
from dicetrace.studies.context import Computed, Context, Output, window_ranges
from dicetrace.studies.text import md_table

NAME = "repetition"
WINDOWS = ("zoom-out", "more-out")
#: Depth (z range from 0) of the 3-D stacks over zoom-out and red sea.
STACK_DEPTH = {"zoom-out": 0.25, "red-sea": 0.3}


def stack_study(ctx: Context, name, res_xy, period_xy=None, min_cell=5, min_period_cell=20):
    """One 3-D stack over window ``name``: its numbers, and its label grid."""
    depth = STACK_DEPTH[name]
    win = tuple(window_ranges(name)) + ((0.0, depth),)
    s = ctx.sample(win, (res_xy, res_xy, int(round(depth * (res_xy - 1))) + 1), slice_spec="seed3")
    g, h = s.labels, s.spacing
    out = {"window": win, "res": g.shape, "spacing": h, "n_throws": int(g.size)}
    out["z0"] = slice_joins(g, min_cell)
    if period_xy is not None:
        out["periodic"] = period_overlaps(g, h, win, period_xy, min_period_cell)
    ctx.log(f"stack {name}: {g.shape}, z0 cells {out['z0']}")
    return out, g


def compute(ctx: Context) -> Computed:
    res = ctx.res(401, 61)
    sigma = max(1.0, 0.015 * (res - 1))  # 1.5 % of the window
    prow, summary, fields = [], {}, {}
    for w in WINDOWS:
        s = ctx.sample(w, res)
        g, h = s.labels, s.spacing
        c_out = label_autocorrelation(g)
        per_out = find_periods(g, spacing=h, min_strength=0.3)
        per_out_weak = find_periods(g, spacing=h, min_strength=0.1)
        tex = texture_labels(g, sigma)
        c_tex = label_autocorrelation(tex)
        rows_tex = periods_rows(find_periods(tex, spacing=h, min_strength=0.1), w, "texture")
        prow += periods_rows(per_out, w, "outcome (≥0.3)") + periods_rows(per_out_weak, w, "outcome (≥0.1)") + rows_tex
        summary[w] = {
            "res": res, "spacing": h[0], "sigma_nodes": sigma,
            "outcome_periods": periods_rows(per_out, w, "outcome"),
            "outcome_periods_weak": periods_rows(per_out_weak, w, "outcome"),
            "outcome_offcentre_max_corr": off_centre_max(c_out, int(0.05 * res)),
            "texture_periods": rows_tex,
            "texture_offcentre_max_corr": off_centre_max(c_tex, int(0.05 * res)),
            "texture_stripe_spacing": stripe_spacing(rows_tex),
        }
        fields[w] = (g, s.extent, c_out, c_tex, rows_tex)
        ctx.log(f"{w}: outcome periods {len(per_out)} (weak {len(per_out_weak)}), texture {rows_tex}")
    # 3-D stacks with equal spacing on all axes
    stacks = {}
    zo_per = [(r["dx"], r["dy"]) for r in summary["zoom-out"]["texture_periods"]]
    stacks["zoom-out"], _ = stack_study(ctx, "zoom-out", ctx.pick(121, 25), period_xy=zo_per)
    stacks["red-sea"], g3 = stack_study(ctx, "red-sea", ctx.pick(101, 21))
    # the largest red (face 3) 2-D cells of the red-sea slice: one 3-D cell?
    t = slice_cell_components(g3, 0)
    top = t[(t["label"] == 3)].sort_values("size", ascending=False).head(10)
    stacks["red-sea"]["red_top10"] = [{"size": int(r.size), "component_3d": int(r.component_3d)}
                                      for r in top.itertuples()]
    stacks["red-sea"]["red_top10_components"] = int(top["component_3d"].nunique())
    ids3, _ = label_cells(g3)
    comp_sizes = np.bincount(ids3.ravel())
    results = {"windows": summary, "stacks": stacks, "largest_3d_cell_frac": float(comp_sizes[1:].max() / g3.size)}
    return Computed(results, {"fields": fields, "red_sea_stack": g3, "periods": prow})


def render(c: Computed, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    fields = c.plot["fields"]
    fig, axes = plt.subplots(len(WINDOWS), 3, figsize=(14, 4.4 * len(WINDOWS)))
    for row, w in enumerate(WINDOWS):
        g, ext, c_out, c_tex, rows_tex = fields[w]
        plot_outcome_map(g, extent=ext, ax=axes[row, 0], legend=False, title=f"{w}: outcomes")
        lx, ly = ext[0][1] - ext[0][0], ext[1][1] - ext[1][0]
        for ax, corr, ttl in ((axes[row, 1], c_out, "autocorrelation of outcomes"),
                              (axes[row, 2], c_tex, "autocorrelation of border density")):
            im = ax.imshow(corr.T, origin="lower", extent=(-lx, lx, -ly, ly), vmin=-0.1, vmax=0.4, cmap="viridis")
            ax.set_title(f"{w}: {ttl}", fontsize=9)
            ax.set_xlabel("lag Δx")
            ax.set_ylabel("lag Δy")
        for r in rows_tex:
            axes[row, 2].annotate("", xy=(r["dx"], r["dy"]), xytext=(0, 0),
                                  arrowprops=dict(arrowstyle="->", color="red", lw=1.5))
        fig.colorbar(im, ax=axes[row, 2], fraction=0.046)
    fig.tight_layout()
    out.save_fig(fig, "c_periods", caption="Left: outcome maps. Middle: autocorrelation of the outcome labels "
                 "(no off-centre peak: the outcomes do not repeat). Right: autocorrelation of the border-density "
                 "texture, with the period vectors found (red arrows).")
    # slices z=0 and z=max of the red-sea stack
    g3 = c.plot["red_sea_stack"]
    depth = STACK_DEPTH["red-sea"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.4))
    for ax, k in zip(axes, (0, g3.shape[2] - 1)):
        plot_outcome_map(g3[:, :, k], extent=list(window_ranges("red-sea")), ax=ax, legend=False,
                         title=f"red sea, z = {depth * k / (g3.shape[2] - 1):.2f}")
    fig.tight_layout()
    out.save_fig(fig, "c_redsea_stack_ends", caption="The red-sea window at the two ends of the 3-D stack.")

    rows = []
    for key, sres in c.results["stacks"].items():
        z = sres["z0"]
        rows.append({"stack": key, "grid": "×".join(str(v) for v in sres["res"]), "spacing": sres["spacing"][0],
                     "cells": z["n_cells_2d"], "big": z[[k for k in z if k.startswith("n_cells_2d_ge")][0]],
                     "comps": z["n_components_3d_of_those"], "joined": z["frac_cells_joined"],
                     "area": z["frac_area_joined"],
                     "half": (f"{z['half_res']['n_cells_2d_big']} → {z['half_res']['n_components_3d_of_those']}"
                              if "half_res" in z else "–")})
    out.tables["stacks"] = md_table(rows, [
        ("stack", "stack", ""), ("grid", "grid", ""), ("spacing", "spacing", ".4g"),
        ("cells", "2-D cells at z=0", "d"), ("big", "of them ≥ 5 nodes", "d"),
        ("comps", "3-D cells they belong to", "d"), ("joined", "fraction sharing a 3-D cell with another 2-D cell", ".3f"),
        ("area", "area fraction joined", ".3f"), ("half", "same at half resolution", "")])
    prows = [{"period": f"({p['period'][0]:.4f}, {p['period'][1]:.4f})", "nodes": str(p["period_nodes"]),
              "n": p["n_cells_tested"], "nb": p["n_big_matched"], "ov": p["median_overlap_big"],
              "conn": p["frac_connected_big"], "conn_all": p["frac_connected_all"]}
             for p in c.results["stacks"]["zoom-out"].get("periodic", [])]
    out.tables["periodic_connected"] = md_table(prows, [
        ("period", "period vector (x, y)", ""), ("nodes", "in stack nodes", ""),
        ("n", "2-D cells with a same-face partner", "d"),
        ("ov", "median overlap, cells ≥ 20 nodes", ".3f"),
        ("nb", "cells ≥ 20 nodes with overlap > 0.5", "d"),
        ("conn", "of those, same 3-D cell", ".3f"), ("conn_all", "same 3-D cell, all cells", ".3f")])
    out.tables["periods"] = md_table(c.plot["periods"], [
        ("window", "window", ""), ("field", "field", ""), ("di", "di", "d"), ("dj", "dj", "d"),
        ("dx", "Δx", ".4g"), ("dy", "Δy", ".4g"), ("length", "length", ".4g"), ("strength", "strength", ".3f")])
