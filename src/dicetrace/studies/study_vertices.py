"""Study f (vertices): the vertex hunt (writeup 4.3 and 5.4).

A vertex of the 2-D cell picture is a point where three (or more) cells
meet. The writeup zoomed in on one and "soon lost the vertex"; its program's
interactive scatter keeps that hunt as a chain of windows below green
island (green_island/g_2 … g_6.2_4, in ``dicetrace.ics.WINDOWS``). Here:

1. ``find_vertices`` refines candidate squares with the simulator itself
   down to 1e-9 (slice units) in the party, green-island and home windows
   and in the program's deepest green-island window.
2. The program's green-island chain is re-drawn (zoom series), and in each
   window the squares (of 1, 2, 4, 8 grid intervals) holding three outcomes
   or more are counted: an isolated vertex gives a count that does not grow
   as the squares shrink (dimension 0); three outcomes meeting along curves
   give a count growing like 1/size (dimension 1).
"""

from __future__ import annotations

import numpy as np

from dicetrace.analysis import fit_power_law
from dicetrace.analysis.plot import plot_zoom_series
from dicetrace.analysis.simulator import classify_on_slice
from dicetrace.analysis.vertices import guarded_find_vertices, triple_boxes
from dicetrace.studies.context import Computed, Context, Output, window_ranges
from dicetrace.studies.text import md_table, pm

NAME = "vertices"
CHAIN = ["home", "green-island", "green-island-2", "green-island-3", "green-island-4", "green-island-5",
         "green-island-6.2-4"]
#: (window, start grid, quick start grid, max squares) of each hunt.
HUNTS = (("party", 41, 21, 256), ("green-island", 41, 21, 256), ("home", 41, 21, 256),
         ("green-island-5", 21, 11, 256), ("green-island-5", 21, 11, 1024))


def hunt(ctx: Context, classify, window, res_full, res_quick, max_squares) -> dict:
    """One ``find_vertices`` run (memory-guarded) and what it found."""
    (x0, x1), (y0, y1) = window_ranges(window)
    n0 = classify.n_evals
    row = {"window": window, "res": ctx.pick(res_full, res_quick), "max_squares": ctx.pick(max_squares, 16)}
    try:
        df = guarded_find_vertices(classify, (x0, x1), (y0, y1), row["res"], tol=1e-9,
                                   max_squares=row["max_squares"], exclude=(-1, 0))
        row["status_counts"] = df["status"].value_counts().to_dict()
        row["n_vertex"] = int((df["status"] == "vertex").sum())
        row["deepest_size"] = float(df[["size_x", "size_y"]].max(axis=1).min()) if len(df) else None
        row["max_depth_reached"] = int(df["depth"].max()) if len(df) else 0
        row["rows"] = df.assign(labels=df["labels"].map(lambda t: "".join(str(v) for v in t))).to_dict("records")
        row["error"] = None
    except MemoryError as e:  # find_vertices draws each root's squares on a dense image
        row["error"] = f"MemoryError in find_vertices ({e.__class__.__name__})"
        row["status_counts"] = {}
    row["n_evals"] = classify.n_evals - n0
    ctx.log(f"{window}: {row['status_counts']} ({row['n_evals']} throws) {row.get('error') or ''}")
    return row


def compute(ctx: Context) -> Computed:
    classify = classify_on_slice("seed")
    hunts = [hunt(ctx, classify, *h) for h in HUNTS]
    # the program's green-island hunt as a zoom series, and triple-square counts
    res = ctx.res(301, 41)
    chain = [ctx.sample(w, res) for w in CHAIN]
    sizes = [b for b in (1, 2, 4, 8) if b < (res - 1) // 2]
    trip = []
    for w, s in zip(CHAIN, chain):
        counts = [triple_boxes(s.labels, b) for b in sizes]
        row = {"window": w, "width": s.window[0][1] - s.window[0][0], "counts": counts}
        try:
            fit = fit_power_law(sizes, counts)
            row["dimension"], row["dimension_stderr"] = -fit.slope, fit.slope_stderr
        except ValueError:
            row["dimension"], row["dimension_stderr"] = None, None
        trip.append(row)
    results = {"hunts": hunts, "triple_squares": {"sizes": sizes, "rows": trip, "res": res}, "res": res,
               "classify_evals": classify.n_evals}
    return Computed(results, {"chain": chain})


def render(c: Computed, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    R = c.results
    out.tables["hunts"] = md_table([{
        "window": h["window"], "res": h["res"], "msq": h["max_squares"],
        "st": ", ".join(f"{k}: {v}" for k, v in sorted(h["status_counts"].items())) or h.get("error"),
        "depth": h.get("max_depth_reached"), "size": h.get("deepest_size"), "evals": h["n_evals"]}
        for h in R["hunts"]], [("window", "window", ""), ("res", "start grid", "d"), ("msq", "max squares", "d"),
                               ("st", "result (roots)", ""),
                               ("depth", "deepest level", "d"), ("size", "smallest cluster (slice units)", ".2g"),
                               ("evals", "throws", "d")])
    chain = c.plot["chain"]
    fig = plot_zoom_series([s.labels for s in chain], [s.extent for s in chain], titles=CHAIN, ncols=4)
    out.save_fig(fig, "f_green_island_chain", caption="The program's vertex hunt below green island "
                 "(its interactive-scatter windows), each framed in white in the one before.")
    ts = R["triple_squares"]
    sizes, trip = ts["sizes"], ts["rows"]
    out.tables["triple_squares"] = md_table([
        {"window": r["window"], "width": r["width"], **{f"b{b}": n for b, n in zip(sizes, r["counts"])},
         "dim": pm(r["dimension"], r["dimension_stderr"], ".2f") if r["dimension"] is not None else "–"}
        for r in trip], [("window", "window", ""), ("width", "x width", ".3g")] +
        [(f"b{b}", f"squares of {b} intervals", "d") for b in sizes] + [("dim", "dimension of the triple set", "")])
    fig, ax = plt.subplots(figsize=(6, 4.3))
    for r in trip:
        n = np.array(r["counts"], dtype=float)
        ok = n > 0
        if ok.any():
            ax.loglog(np.array(sizes)[ok], n[ok], "o-", ms=3, label=r["window"])
    out.save_plot(fig, ax, "f_triple_squares", xlabel="square side (grid intervals)",
                  ylabel="squares holding ≥ 3 outcomes", title=f"Where three outcomes meet ({ts['res']}² grids)",
                  caption="Number of squares holding three outcomes or more against their size, in each window of "
                  "the chain: slope −1 means the triple set is a curve, 0 a point.")
