"""Study f: the vertex hunt (writeup 4.3 and 5.4).

A vertex of the 2-D cell picture is a point where three (or more) cells
meet. The writeup zoomed in on one and "soon lost the vertex"; its program's
interactive scatter keeps that hunt as a chain of windows below green
island (green_island/g_2 … g_6.2_4). Here:

1. ``find_vertices`` refines candidate squares with the simulator itself
   down to 1e-9 (slice units) in the party, green-island and home windows
   and in the program's deepest green-island window.
2. The program's green-island chain is re-drawn (zoom series), and in each
   window the squares (of 1, 2, 4, 8 grid intervals) holding three outcomes
   or more are counted: an isolated vertex gives a count that does not grow
   as the squares shrink (dimension 0); three outcomes meeting along curves
   give a count growing like 1/size (dimension 1).

    python analysis/f_vertices.py [--quick] [--res N] [--out DIR]
"""

from __future__ import annotations

import sys

import numpy as np

import _common as C

NAME = "vertices"
CHAIN = ["home", "green-island", "green-island-2", "green-island-3", "green-island-4", "green-island-5",
         "green-island-6.2-4"]


class _GuardedNumpy:
    """numpy, except that ``zeros`` refuses arrays above ``limit`` elements (raises MemoryError).

    ``find_vertices`` draws the squares of each root on a dense boolean image spanning their bounding
    box at the current level; when a root's squares are spread out at a deep level that image needs
    terabytes. This guard turns that into a reported failure instead of exhausting memory (see the
    report's "needed changes").
    """

    def __init__(self, limit: int):
        self._limit = int(limit)

    def __getattr__(self, name):
        return getattr(np, name)

    def zeros(self, shape, *a, **k):
        if int(np.prod(shape, dtype=np.float64)) > self._limit:
            raise MemoryError(f"find_vertices asked for a {shape} image")
        return np.zeros(shape, *a, **k)


def guarded_find_vertices(*a, limit: int = 50_000_000, **k):
    from dicetrace.analysis import vertices as V

    saved = V.np
    V.np = _GuardedNumpy(limit)
    try:
        return V.find_vertices(*a, **k)
    finally:
        V.np = saved


def triple_boxes(g: np.ndarray, b: int) -> int:
    """Number of closed b×b-interval squares of the grid holding ≥ 3 outcomes (1..6)."""
    count = np.zeros(((g.shape[0] - 1) // b, (g.shape[1] - 1) // b), dtype=np.int64)
    for lab in range(1, 7):
        ind = (g == lab)
        if not ind.any():
            continue
        win = np.lib.stride_tricks.sliding_window_view(ind, (b + 1, b + 1))[::b, ::b]
        count += win[: count.shape[0], : count.shape[1]].any(axis=(2, 3))
    return int((count >= 3).sum())


def main(argv=None) -> dict:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    st = C.Study(NAME, args)
    import matplotlib.pyplot as plt

    from dicetrace.analysis import fit_power_law
    from dicetrace.analysis.plot import plot_zoom_series
    from dicetrace.analysis.simulator import classify_on_slice

    classify = classify_on_slice("seed")
    hunts = []
    targets = [("party", 41, 21, 256), ("green-island", 41, 21, 256), ("home", 41, 21, 256),
               ("green-island-5", 21, 11, 256), ("green-island-5", 21, 11, 1024)]
    for w, rf, rq, msq in targets:
        (x0, x1), (y0, y1) = C.window_ranges(w)
        n0 = classify.n_evals
        row = {"window": w, "res": st.pick(rf, rq), "max_squares": st.pick(msq, 16)}
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
        hunts.append(row)
        st.log(f"{w}: {row['status_counts']} ({row['n_evals']} throws) {row.get('error') or ''}")
    st.results["hunts"] = hunts
    st.results["tables"]["hunts"] = C.md_table([{
        "window": h["window"], "res": h["res"], "msq": h["max_squares"],
        "st": ", ".join(f"{k}: {v}" for k, v in sorted(h["status_counts"].items())) or h.get("error"),
        "depth": h.get("max_depth_reached"), "size": h.get("deepest_size"), "evals": h["n_evals"]}
        for h in hunts], [("window", "window", ""), ("res", "start grid", "d"), ("msq", "max squares", "d"),
                          ("st", "result (roots)", ""),
                          ("depth", "deepest level", "d"), ("size", "smallest cluster (slice units)", ".2g"),
                          ("evals", "throws", "d")])

    # the program's green-island hunt as a zoom series, and triple-square counts
    res = st.res(301, 41)
    chain = [st.sample(C.window_ranges(w), res) for w in CHAIN]
    fig = plot_zoom_series([s.labels for s in chain], [s.extent for s in chain], titles=CHAIN, ncols=4)
    st.save_fig(fig, "f_green_island_chain", caption="The program's vertex hunt below green island "
                "(its interactive-scatter windows), each framed in white in the one before.")
    trip = []
    sizes = [b for b in (1, 2, 4, 8) if b < (res - 1) // 2]
    for w, s in zip(CHAIN, chain):
        counts = [triple_boxes(s.labels, b) for b in sizes]
        row = {"window": w, "width": s.window[0][1] - s.window[0][0], "counts": counts}
        try:
            fit = fit_power_law(sizes, counts)
            row["dimension"], row["dimension_stderr"] = -fit.slope, fit.slope_stderr
        except ValueError:
            row["dimension"], row["dimension_stderr"] = None, None
        trip.append(row)
    st.results["triple_squares"] = {"sizes": sizes, "rows": trip, "res": res}
    st.results["tables"]["triple_squares"] = C.md_table([
        {"window": r["window"], "width": r["width"], **{f"b{b}": c for b, c in zip(sizes, r["counts"])},
         "dim": C.pm(r["dimension"], r["dimension_stderr"], ".2f") if r["dimension"] is not None else "–"}
        for r in trip], [("window", "window", ""), ("width", "x width", ".3g")] +
        [(f"b{b}", f"squares of {b} intervals", "d") for b in sizes] + [("dim", "dimension of the triple set", "")])
    fig, ax = plt.subplots(figsize=(6, 4.3))
    for r in trip:
        c = np.array(r["counts"], dtype=float)
        ok = c > 0
        if ok.any():
            ax.loglog(np.array(sizes)[ok], c[ok], "o-", ms=3, label=r["window"])
    ax.set_xlabel("square side (grid intervals)")
    ax.set_ylabel("squares holding ≥ 3 outcomes")
    ax.set_title(f"Where three outcomes meet ({res}² grids)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    st.save_fig(fig, "f_triple_squares", caption="Number of squares holding three outcomes or more against "
                "their size, in each window of the chain: slope −1 means the triple set is a curve, 0 a point.")
    st.results["res"] = res
    st.results["classify_evals"] = classify.n_evals
    st.write()
    return st.results


if __name__ == "__main__":
    main(sys.argv[1:])
