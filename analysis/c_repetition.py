"""Study c: repetition (writeup 5.1) — period vectors, and one cell or many?

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

    python analysis/c_repetition.py [--quick] [--res N] [--out DIR]
"""

from __future__ import annotations

import math
import sys

import numpy as np

import _common as C

NAME = "repetition"
WINDOWS = ("zoom-out", "more-out")


def texture_labels(grid: np.ndarray, sigma_nodes: float) -> np.ndarray:
    """1 where the smoothed density of cell borders is above its median, else 0."""
    from scipy import ndimage

    from dicetrace.analysis import boundary_mask

    dens = ndimage.gaussian_filter(boundary_mask(grid).astype(float), sigma_nodes)
    return (dens > np.median(dens)).astype(np.int64)


def off_centre_max(C_: np.ndarray, exclude_radius: int) -> float:
    n0, n1 = (C_.shape[0] - 1) // 2, (C_.shape[1] - 1) // 2
    i, j = np.indices(C_.shape)
    far = (i - n0) ** 2 + (j - n1) ** 2 > exclude_radius**2
    inner = (np.abs(i - n0) <= n0 // 2) & (np.abs(j - n1) <= n1 // 2)
    return float(C_[far & inner].max())


def periods_rows(df, window: str, kind: str) -> list[dict]:
    return [{"window": window, "field": kind, "di": int(r.di), "dj": int(r.dj), "dx": float(r.dx), "dy": float(r.dy),
             "length": float(r.length), "strength": float(r.strength)} for r in df.itertuples()]


def stripe_spacing(rows: list[dict]) -> float | None:
    """Distance between stripes: |v1 × v2| / |v1| for a 2-vector basis (v1 the shorter)."""
    if len(rows) < 2:
        return None
    v1 = np.array([rows[0]["dx"], rows[0]["dy"]])
    v2 = np.array([rows[1]["dx"], rows[1]["dy"]])
    return float(abs(v1[0] * v2[1] - v1[1] * v2[0]) / np.linalg.norm(v1))


def stack_study(st, name, window_xy, z_range, res_xy, res_z, period_xy=None, min_cell=5,
                min_period_cell=20) -> dict:
    from dicetrace.analysis import periodic_cells_connected, slice_cell_components

    win = tuple(window_xy) + (tuple(z_range),)
    s = st.sample(win, (res_xy, res_xy, res_z), slice_spec="seed3")
    g = s.labels
    h = s.spacing
    out = {"window": win, "res": g.shape, "spacing": h, "n_throws": int(g.size)}
    # how many 2-D cells of slice z=0 share a 3-D component with another 2-D cell of that slice
    for k, tag in ((0, "z0"),):
        t = slice_cell_components(g, k)
        big = t[t["size"] >= min_cell]
        area = big["size"].sum()
        joined = big[big["n_cells_in_component"] > 1]
        n_comp = big["component_3d"].nunique()
        out[tag] = {
            "n_cells_2d": int(len(t)), f"n_cells_2d_ge{min_cell}": int(len(big)),
            "n_components_3d_of_those": int(n_comp),
            "frac_cells_joined": float(len(joined) / max(len(big), 1)),
            "frac_area_joined": float(joined["size"].sum() / max(area, 1)),
        }
        # per label: 2-D cells -> 3-D components
        per = []
        for lab, grp in big.groupby("label"):
            per.append({"label": int(lab), "cells_2d": int(len(grp)), "components_3d": int(grp["component_3d"].nunique())})
        out[tag]["per_label"] = per
        # same at half the resolution in all three axes (is the answer resolution-dependent?)
        if min(g.shape) >= 9:
            g2 = g[::2, ::2, ::2]
            t2 = slice_cell_components(g2, 0)
            b2 = t2[t2["size"] >= max(2, min_cell // 4)]
            out[tag]["half_res"] = {
                "res": g2.shape, "n_cells_2d_big": int(len(b2)),
                "n_components_3d_of_those": int(b2["component_3d"].nunique()),
                "frac_cells_joined": float((b2["n_cells_in_component"] > 1).sum() / max(len(b2), 1)),
            }
    if period_xy is not None:
        from dicetrace.analysis import cells_table

        sizes = cells_table(g[:, :, 0]).set_index("cell_id")["size"]
        width = min(w[1] - w[0] for w in win[:2])
        res_p = []
        for v in period_xy:
            di, dj = int(round(v[0] / h[0])), int(round(v[1] / h[1]))
            if math.hypot(v[0], v[1]) < 0.05 * width or abs(di) >= g.shape[0] or abs(dj) >= g.shape[1]:
                continue  # the along-stripe vector of a stripe texture (a few nodes): not a repetition
            pc = periodic_cells_connected(g, (di, dj), k=0)
            pc["size"] = sizes.reindex(pc["cell_id"]).to_numpy()
            big = pc[(pc["size"] >= min_period_cell) & (pc["overlap"] > 0.5)]
            res_p.append({
                "period": (float(v[0]), float(v[1])), "period_nodes": (di, dj),
                "n_cells_tested": int(len(pc)),
                "n_big_matched": int(len(big)),
                "min_cell_nodes": min_period_cell,
                "median_overlap_big": float(pc[pc["size"] >= min_period_cell]["overlap"].median())
                if (pc["size"] >= min_period_cell).any() else None,
                "frac_connected_big": float(big["connected"].mean()) if len(big) else None,
                "frac_connected_all": float(pc["connected"].mean()) if len(pc) else None,
            })
        out["periodic"] = res_p
    out["grid"] = g
    st.log(f"stack {name}: {g.shape}, z0 cells {out['z0']}")
    return out


def main(argv=None) -> dict:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    st = C.Study(NAME, args)
    import matplotlib.pyplot as plt

    from dicetrace.analysis import find_periods, label_autocorrelation
    from dicetrace.analysis.plot import plot_outcome_map

    res = st.res(401, 61)
    sigma = max(1.0, 0.015 * (res - 1))  # 1.5 % of the window
    prow, summary, fields = [], {}, {}
    for w in WINDOWS:
        s = st.sample(w, res)
        g = s.labels
        h = s.spacing
        C_out = label_autocorrelation(g)
        per_out = find_periods(g, spacing=h, min_strength=0.3)
        per_out_weak = find_periods(g, spacing=h, min_strength=0.1)
        tex = texture_labels(g, sigma)
        C_tex = label_autocorrelation(tex)
        per_tex = find_periods(tex, spacing=h, min_strength=0.1)
        rows_tex = periods_rows(per_tex, w, "texture")
        prow += periods_rows(per_out, w, "outcome (≥0.3)") + periods_rows(per_out_weak, w, "outcome (≥0.1)") + rows_tex
        summary[w] = {
            "res": res, "spacing": h[0], "sigma_nodes": sigma,
            "outcome_periods": periods_rows(per_out, w, "outcome"),
            "outcome_periods_weak": periods_rows(per_out_weak, w, "outcome"),
            "outcome_offcentre_max_corr": off_centre_max(C_out, int(0.05 * res)),
            "texture_periods": rows_tex,
            "texture_offcentre_max_corr": off_centre_max(C_tex, int(0.05 * res)),
            "texture_stripe_spacing": stripe_spacing(rows_tex),
        }
        fields[w] = (g, s.extent, C_out, C_tex, rows_tex, h)
        st.log(f"{w}: outcome periods {len(per_out)} (weak {len(per_out_weak)}), texture {rows_tex}")

    fig, axes = plt.subplots(len(WINDOWS), 3, figsize=(14, 4.4 * len(WINDOWS)))
    for row, w in enumerate(WINDOWS):
        g, ext, C_out, C_tex, rows_tex, h = fields[w]
        plot_outcome_map(g, extent=ext, ax=axes[row, 0], legend=False, title=f"{w}: outcomes")
        L = (ext[0][1] - ext[0][0])
        lag_ext = (-L, L, -(ext[1][1] - ext[1][0]), ext[1][1] - ext[1][0])
        for ax, Cm, ttl in ((axes[row, 1], C_out, "autocorrelation of outcomes"),
                            (axes[row, 2], C_tex, "autocorrelation of border density")):
            im = ax.imshow(Cm.T, origin="lower", extent=lag_ext, vmin=-0.1, vmax=0.4, cmap="viridis")
            ax.set_title(f"{w}: {ttl}", fontsize=9)
            ax.set_xlabel("lag Δx")
            ax.set_ylabel("lag Δy")
        for r in rows_tex:
            axes[row, 2].annotate("", xy=(r["dx"], r["dy"]), xytext=(0, 0),
                                  arrowprops=dict(arrowstyle="->", color="red", lw=1.5))
        fig.colorbar(im, ax=axes[row, 2], fraction=0.046)
    fig.tight_layout()
    st.save_fig(fig, "c_periods", caption="Left: outcome maps. Middle: autocorrelation of the outcome labels "
                "(no off-centre peak: the outcomes do not repeat). Right: autocorrelation of the border-density "
                "texture, with the period vectors found (red arrows).")

    # 3-D stacks with equal spacing on all axes
    stacks = {}
    zr = st.pick(121, 25)
    zo_per = [(r["dx"], r["dy"]) for r in summary["zoom-out"]["texture_periods"]]
    z_depth = 0.25
    stacks["zoom-out"] = stack_study(st, "zoom-out", ((0.0, 1.0), (0.0, 1.0)), (0.0, z_depth), zr,
                                     int(round(z_depth * (zr - 1))) + 1, period_xy=zo_per)
    rr = st.pick(101, 21)
    stacks["red-sea"] = stack_study(st, "red-sea", ((1.0, 2.0), (3.5, 4.5)), (0.0, 0.3), rr,
                                    int(round(0.3 * (rr - 1))) + 1)
    # the largest red (face 3) 2-D cells of the red-sea slice: one 3-D cell?
    from dicetrace.analysis import label_cells, slice_cell_components

    g3 = stacks["red-sea"]["grid"]
    t = slice_cell_components(g3, 0)
    red = t[(t["label"] == 3)].sort_values("size", ascending=False)
    top = red.head(10)
    stacks["red-sea"]["red_top10"] = [{"size": int(r.size), "component_3d": int(r.component_3d)}
                                      for r in top.itertuples()]
    stacks["red-sea"]["red_top10_components"] = int(top["component_3d"].nunique())
    ids3, n3 = label_cells(g3)
    comp_sizes = np.bincount(ids3.ravel())
    for key in stacks:
        stacks[key].pop("grid")
    # figure: slices z=0 and z=max of the red-sea stack, the big red cells coloured by 3-D component
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.4))
    z_vals = [0, g3.shape[2] - 1]
    ext = [(1.0, 2.0), (3.5, 4.5)]
    for ax, k in zip(axes, z_vals):
        plot_outcome_map(g3[:, :, k], extent=ext, ax=ax, legend=False,
                         title=f"red sea, z = {0.3 * k / (g3.shape[2] - 1):.2f}")
    fig.tight_layout()
    st.save_fig(fig, "c_redsea_stack_ends", caption="The red-sea window at the two ends of the 3-D stack.")

    rows = []
    for key, sres in stacks.items():
        z = sres["z0"]
        rows.append({"stack": key, "grid": "×".join(str(v) for v in sres["res"]), "spacing": sres["spacing"][0],
                     "cells": z["n_cells_2d"], "big": z[[k for k in z if k.startswith("n_cells_2d_ge")][0]],
                     "comps": z["n_components_3d_of_those"], "joined": z["frac_cells_joined"],
                     "area": z["frac_area_joined"],
                     "half": (f"{z['half_res']['n_cells_2d_big']} → {z['half_res']['n_components_3d_of_those']}"
                              if "half_res" in z else "–")})
    st.results["tables"]["stacks"] = C.md_table(rows, [
        ("stack", "stack", ""), ("grid", "grid", ""), ("spacing", "spacing", ".4g"),
        ("cells", "2-D cells at z=0", "d"), ("big", "of them ≥ 5 nodes", "d"),
        ("comps", "3-D cells they belong to", "d"), ("joined", "fraction sharing a 3-D cell with another 2-D cell", ".3f"),
        ("area", "area fraction joined", ".3f"), ("half", "same at half resolution", "")])
    prows = []
    for p in stacks["zoom-out"].get("periodic", []):
        prows.append({"period": f"({p['period'][0]:.4f}, {p['period'][1]:.4f})", "nodes": str(p["period_nodes"]),
                      "n": p["n_cells_tested"], "nb": p["n_big_matched"], "ov": p["median_overlap_big"],
                      "conn": p["frac_connected_big"], "conn_all": p["frac_connected_all"]})
    st.results["tables"]["periodic_connected"] = C.md_table(prows, [
        ("period", "period vector (x, y)", ""), ("nodes", "in stack nodes", ""),
        ("n", "2-D cells with a same-face partner", "d"),
        ("ov", "median overlap, cells ≥ 20 nodes", ".3f"),
        ("nb", "cells ≥ 20 nodes with overlap > 0.5", "d"),
        ("conn", "of those, same 3-D cell", ".3f"), ("conn_all", "same 3-D cell, all cells", ".3f")])
    st.results["tables"]["periods"] = C.md_table(prow, [
        ("window", "window", ""), ("field", "field", ""), ("di", "di", "d"), ("dj", "dj", "d"),
        ("dx", "Δx", ".4g"), ("dy", "Δy", ".4g"), ("length", "length", ".4g"), ("strength", "strength", ".3f")])
    st.results["windows"] = summary
    st.results["stacks"] = stacks
    st.results["largest_3d_cell_frac"] = float(comp_sizes[1:].max() / g3.size)
    st.write()
    return st.results


if __name__ == "__main__":
    main(sys.argv[1:])
