"""Study b: "fractal" zoom series (writeup 5.3) and the measures of the boundaries.

Two zoom series in the writeup's style (each window framed in white in the
one before): more-out → red sea → red sea 2 → deeper, and home → party →
the program's party 2 → party 3. For each of the writeup's eight windows:
the boundary fraction, the uncertainty exponent α (box counting on the grid,
grid resolution, and random-pair perturbation against the simulator), the
box-counting dimension of the boundary, the basin entropies Sb and Sbb
(ln 2 criterion) and the Wada tests (merging, and refinement of boundary
segments with the simulator).

    python analysis/b_fractal.py [--quick] [--res N] [--out DIR]
"""

from __future__ import annotations

import math
import sys

import numpy as np

import _common as C

NAME = "fractal"
EXTRA_WINDOWS = {
    # deeper red-sea zooms chosen inside red sea 2 where its border is richest
    "red-sea-3": ((1.40, 1.45), (3.95, 4.02)),
    "red-sea-4": ((1.405, 1.42), (3.955, 3.975)),
}
SERIES = {
    "red_sea": ["more-out", "red-sea", "red-sea-2", "red-sea-3", "red-sea-4"],
    "party": ["zoom-out", "home", "party", "party-2", "party-3"],
}


def ranges(w):
    return EXTRA_WINDOWS[w] if w in EXTRA_WINDOWS else C.window_ranges(w)


def measures(st, w, s, classify, *, perturb: bool) -> dict:
    from dicetrace.analysis import (
        boundary_dimension,
        chaos_measures,
        uncertainty_exponent_perturbation,
        uncertainty_exponent_resolution,
        wada_grid_test,
        wada_merge_test,
    )

    g = s.labels
    h = s.spacing[0]
    W = s.window[0][1] - s.window[0][0]
    row: dict = {"window": w, "ranges": s.window, "res": g.shape[0], "spacing": h}
    cm = chaos_measures(g, spacing=h, n_blocks=4, n_boot=200, rng=st.rng)
    row.update(cm)
    bd = boundary_dimension(g, method="mask")
    row["dim_mask"], row["dim_mask_stderr"] = bd.dimension, bd.stderr
    if (g.shape[0] - 1) % 4 == 0 and g.shape[0] >= 41:
        ur = uncertainty_exponent_resolution([g, g[::2, ::2], g[::4, ::4]], [h, 2 * h, 4 * h])
        row["alpha_res"], row["alpha_res_f"] = ur.alpha, ur.f
    labs = sorted(set(np.unique(g).tolist()) - {-1, 0})
    row["n_outcomes"] = len(labs)
    if len(labs) >= 3:
        wm = wada_merge_test(g, r_max=5, tol=0.01, exclude=(-1, 0))
        row["wada_merge_r"] = wm.r_wada
        row["wada_merge_far_r5"] = float(wm.far_fraction[-1])
        row["wada_merge_far_r1"] = float(wm.far_fraction[min(1, len(wm.far_fraction) - 1)])
        if perturb:
            wg = wada_grid_test(classify, g, s.extent, max_level=st.pick(12, 4), max_segments=st.pick(300, 20),
                                exclude=(-1, 0), rng=st.rng)
            row["wada_grid_G"] = float(wg.wada_fraction[-1])
            row["wada_grid_G_curve"] = wg.wada_fraction
            row["wada_grid_segments"] = wg.n_segments
            row["wada_grid_levels"] = int(wg.levels[-1])
            row["wada_grid_evals"] = wg.n_evals
            row["wada_grid_wada"] = wg.wada
    if perturb:
        npts = st.pick(4000, 200)
        rel = np.logspace(-8, -2, 7) if not st.quick else np.logspace(-4, -1, 4)
        eps = W * rel
        lo = np.array([r[0] for r in s.window])
        hi = np.array([r[1] for r in s.window])
        pts = lo + st.rng.random((npts, 2)) * (hi - lo)
        try:
            up = uncertainty_exponent_perturbation(classify, pts, eps, st.rng)
            row["alpha_pert"], row["alpha_pert_stderr"] = up.alpha, up.alpha_stderr
            row["pert_f"] = up.f
        except ValueError as e:  # fewer than two eps with a nonzero fraction
            st.log(f"{w}: no perturbation fit ({e})")
            row["alpha_pert"], row["alpha_pert_stderr"] = math.nan, math.nan
            row["pert_f"] = np.full(len(eps), math.nan)
        row["pert_eps"], row["pert_n"] = eps, npts
        row["pert_eps_rel"] = rel
    return row


def main(argv=None) -> dict:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    st = C.Study(NAME, args)
    import matplotlib.pyplot as plt

    from dicetrace.analysis.plot import plot_zoom_series
    from dicetrace.analysis.simulator import classify_on_slice

    res = st.res(401, 41)
    classify = classify_on_slice("seed")
    samples = {}
    for w in list(C.WRITEUP_WINDOWS) + [w for ser in SERIES.values() for w in ser]:
        if w not in samples:
            samples[w] = st.sample(ranges(w), res)

    rows = []
    for w in C.WRITEUP_WINDOWS:
        rows.append(measures(st, w, samples[w], classify, perturb=True))
        r = rows[-1]
        st.log(f"{w}: bf={r['boundary_fraction']:.3f} α_box={r['alpha']:.3f} α_pert={r.get('alpha_pert', math.nan):.3f} "
               f"Sbb={r['Sbb']:.3f}")
    extra = [measures(st, w, samples[w], classify, perturb=False) for w in
             ("red-sea-3", "red-sea-4", "party-2", "party-3")]

    for key, ser in SERIES.items():
        fig = plot_zoom_series([samples[w].labels for w in ser], [samples[w].extent for w in ser],
                               titles=ser, ncols=len(ser))
        st.save_fig(fig, f"b_zoom_{key}", caption=f"Zoom series {' → '.join(ser)} ({res}² each); "
                    "white boxes frame the next window.")

    # f(eps) of the perturbation method
    fig, ax = plt.subplots(figsize=(6.2, 4.6))
    for r in rows:
        if "pert_f" not in r:
            continue
        f = np.asarray(r["pert_f"], dtype=float)
        ok = f > 0
        ax.loglog(np.asarray(r["pert_eps_rel"])[ok], f[ok], "o-", ms=3,
                  label=f"{r['window']} (α={r['alpha_pert']:.2f})")
    ax.set_xlabel("ε / window width")
    ax.set_ylabel("f(ε): fraction of pairs with different outcomes")
    ax.set_title("Uncertainty exponent by random-pair perturbation")
    ax.legend(fontsize=7)
    fig.tight_layout()
    st.save_fig(fig, "b_uncertainty_perturbation", caption="f(ε) against ε/W for the eight windows; "
                "the slope is the uncertainty exponent α.")

    # box-counting f(eps) on the grids
    from dicetrace.analysis import uncertainty_exponent

    fig, ax = plt.subplots(figsize=(6.2, 4.6))
    for w in C.WRITEUP_WINDOWS:
        s = samples[w]
        ue = uncertainty_exponent(s.labels)
        ax.loglog(ue.eps, ue.f, "o-", ms=3, label=f"{w} (α={ue.alpha:.2f})")
    ax.set_xlabel("box side b (grid intervals)")
    ax.set_ylabel("fraction of boxes holding ≥ 2 outcomes")
    ax.set_title(f"Box-counting uncertainty exponent ({res}² grids)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    st.save_fig(fig, "b_uncertainty_boxes", caption="Fraction of uncertain boxes against box size.")

    def fmt_row(r):
        return {
            "window": r["window"], "res": r["res"],
            "bf": C.pm(r["boundary_fraction"], r["boundary_fraction_block_stderr"], ".3f"),
            "a_box": C.pm(r["alpha"], r["alpha_block_stderr"], ".3f"),
            "a_res": r.get("alpha_res"),
            "a_pert": C.pm(r.get("alpha_pert", math.nan), r.get("alpha_pert_stderr"), ".3f"),
            "dim": C.pm(r["dimension"], r["alpha_block_stderr"], ".3f"),
            "dim_mask": C.pm(r["dim_mask"], r["dim_mask_stderr"], ".3f"),
            "Sb": C.pm(r["Sb"], r["Sb_stderr"], ".3f"),
            "Sbb": C.pm(r["Sbb"], r["Sbb_stderr"], ".3f"),
            "ln2": "yes" if r["fractal_boundary"] else "no",
            "n_out": r["n_outcomes"],
            "wada_merge": ("r=" + str(r["wada_merge_r"])) if r.get("wada_merge_r") is not None else (
                f"no (far {r['wada_merge_far_r5']:.2f})" if "wada_merge_far_r5" in r else "–"),
            "wada_grid": (f"G={r['wada_grid_G']:.2f}" if "wada_grid_G" in r else "–"),
        }

    cols = [("window", "window", ""), ("res", "grid", "d"), ("bf", "boundary fraction", ""),
            ("a_box", "α box", ""), ("a_res", "α resolution", ".3f"), ("a_pert", "α perturbation", ""),
            ("dim", "D = 2 − α box", ""), ("dim_mask", "D boundary mask", ""),
            ("Sb", "Sb", ""), ("Sbb", "Sbb", ""), ("ln2", "Sbb > ln 2", ""), ("n_out", "outcomes", "d"),
            ("wada_merge", "Wada merge (r, nodes)", ""), ("wada_grid", "Wada refine G", "")]
    st.results["tables"]["measures"] = C.md_table([fmt_row(r) for r in rows], cols)
    st.results["tables"]["measures_extra"] = C.md_table([fmt_row(r) for r in extra], cols[:5] + cols[6:12])
    pert_rows = []
    for r in rows:
        d = {"window": r["window"]}
        for rel, f in zip(r["pert_eps_rel"], r["pert_f"]):
            d[f"{rel:.0e}"] = f
        pert_rows.append(d)
    rels = [f"{v:.0e}" for v in rows[0]["pert_eps_rel"]]
    st.results["tables"]["perturbation_f"] = C.md_table(pert_rows, [("window", "window", "")] +
                                                        [(k, f"ε/W={k}", ".4f") for k in rels])
    st.results["windows"] = {r["window"]: r for r in rows}
    st.results["extra_windows"] = {r["window"]: r for r in extra}
    st.results["extra_ranges"] = EXTRA_WINDOWS
    st.results["series"] = SERIES
    st.results["res"] = res
    st.results["pert_npts"] = st.pick(4000, 200)
    st.results["classify_evals"] = classify.n_evals
    st.write()
    return st.results


if __name__ == "__main__":
    main(sys.argv[1:])
