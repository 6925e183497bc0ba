"""Study b (fractal): "fractal" zoom series (writeup 5.3) and the measures of the boundaries.

Two zoom series in the writeup's style (each window framed in white in the
one before): more-out → red sea → red sea 2 → deeper, and home → party →
the program's party 2 → party 3. For each of the writeup's eight windows:
the boundary fraction, the uncertainty exponent α (box counting on the grid,
grid resolution, and random-pair perturbation against the simulator), the
box-counting dimension of the boundary, the basin entropies Sb and Sbb
(ln 2 criterion) and the Wada tests (merging, and refinement of boundary
segments with the simulator).
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.analysis import uncertainty_exponent
from dicetrace.analysis.plot import plot_zoom_series
from dicetrace.analysis.simulator import classify_on_slice
from dicetrace.analysis.sweep import map_measures
from dicetrace.studies.context import WRITEUP_WINDOWS, Computed, Context, Output, window_ranges
from dicetrace.studies.text import md_table, pm

NAME = "fractal"
#: Deeper red-sea zooms (in ``dicetrace.ics.WINDOWS``), chosen inside red sea 2 where its border is richest.
DEEP_RED_SEA = ("red-sea-3", "red-sea-4")
SERIES = {
    "red_sea": ["more-out", "red-sea", "red-sea-2", "red-sea-3", "red-sea-4"],
    "party": ["zoom-out", "home", "party", "party-2", "party-3"],
}
#: Windows measured without the simulator-based tests.
EXTRA = ("red-sea-3", "red-sea-4", "party-2", "party-3")


def measures(ctx: Context, w, s, classify, *, perturb: bool, wada_grid: bool = True) -> dict:
    """:func:`~dicetrace.analysis.sweep.map_measures` of one window's map at this run's sizes."""
    return map_measures(w, s, classify, ctx.rng, perturb=perturb, wada_grid=wada_grid,
                        wada_levels=ctx.pick(12, 4), wada_segments=ctx.pick(300, 20), n_points=ctx.pick(4000, 200),
                        eps_rel=np.logspace(-8, -2, 7) if not ctx.quick else np.logspace(-4, -1, 4), log=ctx.log)


def compute(ctx: Context) -> Computed:
    res = ctx.res(401, 41)
    classify = classify_on_slice("seed")
    samples = {}
    for w in list(WRITEUP_WINDOWS) + [w for ser in SERIES.values() for w in ser]:
        if w not in samples:
            samples[w] = ctx.sample(w, res)
    rows = []
    for w in WRITEUP_WINDOWS:
        rows.append(measures(ctx, w, samples[w], classify, perturb=True))
        r = rows[-1]
        ctx.log(f"{w}: bf={r['boundary_fraction']:.3f} α_box={r['alpha']:.3f} "
                f"α_pert={r.get('alpha_pert', math.nan):.3f} Sbb={r['Sbb']:.3f}")
    extra = [measures(ctx, w, samples[w], classify, perturb=False) for w in EXTRA]
    boxes = {w: uncertainty_exponent(samples[w].labels) for w in WRITEUP_WINDOWS}
    results = {
        "windows": {r["window"]: r for r in rows},
        "extra_windows": {r["window"]: r for r in extra},
        "extra_ranges": {w: window_ranges(w) for w in DEEP_RED_SEA},
        "series": SERIES,
        "res": res,
        "pert_npts": ctx.pick(4000, 200),
        "classify_evals": classify.n_evals,
    }
    return Computed(results, {"samples": samples, "boxes": boxes})


def _table_row(r: dict) -> dict:
    return {
        "window": r["window"], "res": r["res"],
        "bf": pm(r["boundary_fraction"], r["boundary_fraction_block_stderr"], ".3f"),
        "a_box": pm(r["alpha"], r["alpha_block_stderr"], ".3f"),
        "a_res": r.get("alpha_res"),
        "a_pert": pm(r.get("alpha_pert", math.nan), r.get("alpha_pert_stderr"), ".3f"),
        "dim": pm(r["dimension"], r["alpha_block_stderr"], ".3f"),
        "dim_mask": pm(r["dim_mask"], r["dim_mask_stderr"], ".3f"),
        "Sb": pm(r["Sb"], r["Sb_stderr"], ".3f"),
        "Sbb": pm(r["Sbb"], r["Sbb_stderr"], ".3f"),
        "ln2": "yes" if r["fractal_boundary"] else "no",
        "n_out": r["n_outcomes"],
        "wada_merge": ("r=" + str(r["wada_merge_r"])) if r.get("wada_merge_r") is not None else (
            f"no (far {r['wada_merge_far_r5']:.2f})" if "wada_merge_far_r5" in r else "–"),
        "wada_grid": (f"G={r['wada_grid_G']:.2f}" if "wada_grid_G" in r else "–"),
    }


def render(c: Computed, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    samples, res = c.plot["samples"], c.results["res"]
    rows = list(c.results["windows"].values())
    for key, ser in SERIES.items():
        fig = plot_zoom_series([samples[w].labels for w in ser], [samples[w].extent for w in ser],
                               titles=ser, ncols=len(ser))
        out.save_fig(fig, f"b_zoom_{key}", caption=f"Zoom series {' → '.join(ser)} ({res}² each); "
                     "white boxes frame the next window.")
    fig, ax = plt.subplots(figsize=(6.2, 4.6))
    for r in rows:
        f = np.asarray(r["pert_f"], dtype=float)
        ok = f > 0
        ax.loglog(np.asarray(r["pert_eps_rel"])[ok], f[ok], "o-", ms=3, label=f"{r['window']} (α={r['alpha_pert']:.2f})")
    out.save_plot(fig, ax, "b_uncertainty_perturbation", xlabel="ε / window width",
                  ylabel="f(ε): fraction of pairs with different outcomes",
                  title="Uncertainty exponent by random-pair perturbation",
                  caption="f(ε) against ε/W for the eight windows; the slope is the uncertainty exponent α.")
    fig, ax = plt.subplots(figsize=(6.2, 4.6))
    for w, ue in c.plot["boxes"].items():
        ax.loglog(ue.eps, ue.f, "o-", ms=3, label=f"{w} (α={ue.alpha:.2f})")
    out.save_plot(fig, ax, "b_uncertainty_boxes", xlabel="box side b (grid intervals)",
                  ylabel="fraction of boxes holding ≥ 2 outcomes", title=f"Box-counting uncertainty exponent ({res}² grids)",
                  caption="Fraction of uncertain boxes against box size.")

    cols = [("window", "window", ""), ("res", "grid", "d"), ("bf", "boundary fraction", ""),
            ("a_box", "α box", ""), ("a_res", "α resolution", ".3f"), ("a_pert", "α perturbation", ""),
            ("dim", "D = 2 − α box", ""), ("dim_mask", "D boundary mask", ""),
            ("Sb", "Sb", ""), ("Sbb", "Sbb", ""), ("ln2", "Sbb > ln 2", ""), ("n_out", "outcomes", "d"),
            ("wada_merge", "Wada merge (r, nodes)", ""), ("wada_grid", "Wada refine G", "")]
    out.tables["measures"] = md_table([_table_row(r) for r in rows], cols)
    out.tables["measures_extra"] = md_table([_table_row(r) for r in c.results["extra_windows"].values()],
                                            cols[:5] + cols[6:12])
    pert_rows = [{"window": r["window"], **{f"{rel:.0e}": f for rel, f in zip(r["pert_eps_rel"], r["pert_f"])}}
                 for r in rows]
    rels = [f"{v:.0e}" for v in rows[0]["pert_eps_rel"]]
    out.tables["perturbation_f"] = md_table(pert_rows, [("window", "window", "")] +
                                            [(k, f"ε/W={k}", ".4f") for k in rels])
