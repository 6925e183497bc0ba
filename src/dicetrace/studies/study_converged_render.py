"""Study l (converged): the write-up -- the per-window tables, the answers, the certificates and the figures.

Everything is drawn from a run's results (``converged.json``), so a finished
run can be rendered again without simulating
(:func:`dicetrace.studies.study_converged.rerender`).
"""

from __future__ import annotations

import numpy as np

from dicetrace.analysis.plot import plot_outcome_map
from dicetrace.integrators import INTEGRATORS
from dicetrace.studies.context import Computed, Output
from dicetrace.studies.study_converged_changes import CHANGE_SIGMA, MEASURES
from dicetrace.studies.text import CONVERGED_MIN, fmt, md_table, pm, tol_text, verdict_word

MODEL_TITLES = {"discrete": "discrete (seed, dt = 1 ms)", "converged": "converged seed", "physical": "physical"}


def verdict_text(r: dict) -> str:
    """"yes" for a certified map whose certificate is at least :data:`CONVERGED_MIN`, "statistics only" for a
    certified one below it, else "**NO**" and why."""
    if r["converged"]:
        return "yes" if r["certificate"]["fraction"] >= CONVERGED_MIN else f"statistics only (certificate < {CONVERGED_MIN:g})"
    return "**NO** (below the floor)" if not r["above_floor"] else "**NO** (agreement at chance)"


def _cert_text(r: dict) -> str:
    c, f = r["certificate"], r["floor"]
    return (f"{c['fraction']:.3f} [{c['ci'][0]:.3f}, {c['ci'][1]:.3f}], κ {c['kappa']:.2f} / floor "
            f"{f['fraction']:.3f} [{f['ci'][0]:.3f}, {f['ci'][1]:.3f}]")


def _numerics(r: dict) -> str:
    """The integrator of a model's row and its tolerance (adaptive) or step (fixed)."""
    if INTEGRATORS[r["integrator"]].adaptive:
        return f"{r['integrator']}, tol {tol_text(r)}"  # rows written before tol_growth: uniform
    return f"{r['integrator']}, dt {1000 * r['dt_s']:g} ms"


def _model_header(r: dict) -> str:
    return f"{r['model']} ({_numerics(r)})"


#: The label of the rows that section o supersedes (λ fitted over every distance, `physical` at its graded tolerance):
#: they keep their numbers as what those fits gave, without a verdict.
SUPERSEDED = "superseded by section o, no verdict"
#: The change keys those rows had.
SUPERSEDED_KEYS = ("lambda",)


def window_table(rows: dict, models, sigma: float = CHANGE_SIGMA) -> str:
    """One window's measures, one column per model, and the discrete → converged change in standard errors."""
    ms = [rows[m] for m in models]
    z = {c["key"]: c for c in rows["changes"]}

    def line(label, vals, key=None):
        r = {"measure": label, **{m: v for m, v in zip(models, vals)}}
        c = z.get(key)
        if c is not None:
            r["z"] = (_p_text(c["converged"]) if c["z"] is None else f"{c['z']:.1f}") + (" **changed**" if c[
                "changed"] else "")
        return r

    def face(k):
        f = [r["fractions"].get(str(k), {}) for r in ms]  # keys are strings, as in the JSON
        return [pm(x.get("fraction"), x.get("block_stderr"), ".3f") for x in f]

    lines = [
        line("integrator", [_numerics(r) for r in ms]),
        line("certificate (10× tighter) / chaos floor", [_cert_text(r) for r in ms]),
        line("converged", [verdict_text(r) for r in ms]),
        line("agreement with the discrete map (κ)", ["–"] + [
            f"{r['agreement_with_discrete']['fraction']:.3f} (κ {r['agreement_with_discrete']['kappa']:.2f})"
            for r in ms[1:]]),
        line("cells", [str(r["cells"]["n_cells"]) for r in ms]),
        line("cells / 1000 nodes", [f"{r['cells']['cells_per_1000_nodes']:.1f}" for r in ms]),
        line("nodes in 1-node cells", [f"{r['cells']['frac_nodes_in_singletons']:.3f}" for r in ms]),
        line("largest cell (fraction, face)", [f"{r['cells']['largest_cell_frac']:.4f} ({r['cells']['largest_cell_label']})"
                                               for r in ms]),
        line("median cell (nodes)", [f"{r['cells']['median_size']:.0f}" for r in ms]),
        *[line(f"face {k} fraction", face(k)) for k in range(1, 7)],
        line("face counts vs discrete: χ² p", ["–"] + [_p_text(r.get("chi2_p_vs_discrete")) for r in ms[1:]], "faces"),
        line("boundary fraction", [pm(r["boundary_fraction"], r["boundary_fraction_block_stderr"]) for r in ms],
             "boundary_fraction"),
        line("α boxes", [pm(*MEASURES["alpha_box"](r)) for r in ms], "alpha_box"),
        line("α resolution", [fmt(r.get("alpha_res"), ".3f") for r in ms]),
        line("α perturbation", [pm(r.get("alpha_pert"), r.get("alpha_pert_stderr")) for r in ms], "alpha_pert"),
        line("D = 2 − α boxes", [f"{r['dimension']:.3f}" for r in ms]),
        line("D boundary mask", [pm(r["dim_mask"], r["dim_mask_stderr"]) for r in ms], "dim_mask"),
        line("Sb", [pm(r["Sb"], r["Sb_stderr"]) for r in ms], "Sb"),
        line("Sbb (> ln 2?)", [f"{pm(r['Sbb'], r['Sbb_stderr'])} ({'yes' if r['fractal_boundary'] else 'no'})"
                               for r in ms], "Sbb"),
        line("Wada merge", [("r=" + str(r["wada_merge_r"])) if r.get("wada_merge_r") is not None else
                            (f"no (far {r['wada_merge_far_r5']:.2f})" if "wada_merge_far_r5" in r else "–") for r in ms]),
        line("settle time mean (s)", [pm(r["settle"]["mean"], r["settle"]["mean_stderr"], ".4f") for r in ms],
             "settle_mean"),
        line("settle time median / 90 % / max (s)", [f"{r['settle']['median']:.2f} / {r['settle']['q90']:.2f} / "
                                                     f"{r['settle']['max']:.2f}" for r in ms]),
        line("settle time at borders / inside cells (s)", [f"{fmt(r['settle']['border_mean'], '.2f')} / "
                                                           f"{fmt(r['settle']['interior_mean'], '.2f')}" for r in ms]),
        line("unsettled throws", [str(r["settle"]["n_unsettled"]) for r in ms]),
        line("escape rate κ (1/s)", [pm(r["settle"].get("kappa"), r["settle"].get("kappa_stderr"), ".1f") for r in ms],
             "kappa"),
        line(f"settle-time divergence λ, all sides (1/s): {SUPERSEDED}", [
            f"{pm(r['divergence'].get('mean'), r['divergence'].get('mean_stderr'), '.1f')} "
            f"({r['divergence']['n_fits']} sides)" for r in ms]),
        line(f"λ median ± bootstrap / clean fits (1/s): {SUPERSEDED}", [
            f"{pm(r['divergence'].get('median'), r['divergence'].get('median_stderr'), '.1f')} / "
            f"{pm(r['divergence'].get('clean_mean'), r['divergence'].get('clean_stderr'), '.1f')} "
            f"({r['divergence']['n_clean']})" for r in ms]),
        line("outcome autocorrelation, largest off-centre", [f"{r['repetition']['outcome_offcentre_max_corr']:.2f}"
                                                             for r in ms]),
        line("outcome period vectors (Δx, Δy; strength ≥ 0.3)", [", ".join(
            f"({p['dx']:.3g}, {p['dy']:.3g}; {p['strength']:.2f})" for p in r["repetition"].get("outcome_periods", [])[:2])
            or "none" for r in ms]),
        line("texture period vectors (Δx, Δy)", [", ".join(f"({p['dx']:.3g}, {p['dy']:.3g})" for p in
                                                           r["repetition"]["texture_periods"][:2]) or "none"
                                                 for r in ms]),
        line("texture stripe spacing", [fmt(r["repetition"]["texture_stripe_spacing"], ".3g") for r in ms]),
    ]
    cols = [("measure", "measure", "")] + [(m, _model_header(r), "") for m, r in zip(models, ms)] + [
        ("z", f"discrete → converged (σ; changed > {sigma:g} σ)", "")]
    return md_table(lines, cols)


def changes_text(by: dict, windows, sigma: float = CHANGE_SIGMA) -> str:
    """A list, per window, of the measures that change from the discrete to the converged model."""
    lines = []
    for w in windows:
        ch = [c for c in by[w]["changes"] if c["key"] not in SUPERSEDED_KEYS]
        yes = [c for c in ch if c["changed"]]
        no = [c for c in ch if not c["changed"]]
        conv = by[w]["converged"]
        tag = "" if conv["converged"] else " (the converged map is **not certified**: read with care)"
        desc = "; ".join(f"{c['measure']} {_fmt_change(c)}" for c in yes) or "nothing beyond the error bars"
        lines.append(f"- **{w}**{tag}: changed: {desc}. Unchanged within {sigma:g} σ: "
                     f"{', '.join(c['measure'] for c in no) or 'none'}. (The settle-time divergence λ over every "
                     "distance is superseded by section o and judged there.)")
    return "\n".join(lines)


def _p_text(p) -> str:
    """A p-value; one that underflows to 0 as an upper bound."""
    if p is None:
        return "–"
    return "p < 1e-300" if p == 0 else f"p = {p:.1e}"


def _fmt_change(c: dict) -> str:
    if c["z"] is None:
        return f"({_p_text(c['converged'])})"
    return f"{c['discrete']:.3g} → {c['converged']:.3g} ({c['z']:.0f} σ)"


def answers(by: dict, summary: dict, windows, sigma: float = CHANGE_SIGMA) -> dict[str, str]:
    """The "converged model" cells of the answers table (Markdown, no line breaks)."""
    c = {w: by[w]["converged"] for w in windows}
    rep = {w: c[w]["repetition"] for w in ("zoom-out", "more-out")}
    tex = rep["zoom-out"]["texture_periods"]
    s = summary["converged"]
    cert = f"{s['n_converged']} of {s['n_maps']} converged-seed maps certified"
    return {
        "periods": ("Largest off-centre autocorrelation of the outcomes "
                    f"{rep['zoom-out']['outcome_offcentre_max_corr']:.2f} (zoom-out), "
                    f"{rep['more-out']['outcome_offcentre_max_corr']:.2f} (more-out), "
                    f"{c['home']['repetition']['outcome_offcentre_max_corr']:.2f} (home); outcome period vectors "
                    "of strength ≥ 0.3: " + "; ".join(
                        f"{w} " + (", ".join(f"({p['dx']:.4g}, {p['dy']:.4g}), {p['length'] / c[w]['spacing']:.1f} "
                                             "grid nodes long" for p in c[w]["repetition"].get("outcome_periods", [])[:2])
                                   or "none") for w in ("home", "zoom-out", "more-out"))
                    + " (a lag of a few nodes is the size of the larger cells, not a repetition)"
                    + ". Texture periods in zoom-out: "
                    + (", ".join(f"({p['dx']:.4f}, {p['dy']:.4f})" for p in tex[:2]) or "none")
                    + f"; more-out texture stripe spacing {fmt(rep['more-out']['texture_stripe_spacing'], '.2f')}."),
        "alpha": (f"α (perturbation) from {fmt(s['alpha_pert_min'], '.2f')} to {fmt(s['alpha_pert_max'], '.2f')} "
                  f"over home, zoom-out, more-out, red sea (discrete, same grids: "
                  f"{fmt(summary['discrete']['alpha_pert_min'], '.2f')}–{fmt(summary['discrete']['alpha_pert_max'], '.2f')}); "
                  f"boundary-mask dimension {fmt(s['dim_mask_min'], '.2f')}–{fmt(s['dim_mask_max'], '.2f')}. "
                  f"Table in section l ({cert})."),
        "lambda": ("Settle-time divergence T ≈ T0 − ln(d)/λ at borders of the converged maps, all fitted sides "
                   "(no selection): " + "; ".join(
                       f"{w} {pm(c[w]['divergence'].get('mean'), c[w]['divergence'].get('mean_stderr'), '.1f')} /s "
                       f"(discrete {pm(by[w]['discrete']['divergence'].get('mean'), by[w]['discrete']['divergence'].get('mean_stderr'), '.1f')})"
                       for w in windows) + "."),
        "changes": (f"Certified (section l): {cert}, {summary['physical']['n_converged']} of "
                    f"{summary['physical']['n_maps']} physical maps, {summary['discrete']['n_converged']} of "
                    f"{summary['discrete']['n_maps']} discrete ones. Beyond {sigma:g} σ, converging changes: "
                    + "; ".join(f"{w}: {', '.join(summary['changed'][w]) or 'nothing'}" for w in windows) + "."),
    }


def render(c: Computed, out: Output) -> None:
    """The study's figures and tables, from the run's results (its windows, models and threshold as it ran)."""
    import matplotlib.pyplot as plt  # heavy, optional: only rendering needs it

    by, res = c.results["by"], c.results["res"]
    windows, models = tuple(c.results["windows"]), tuple(c.results["models"])
    sigma = c.results.get("change_sigma", CHANGE_SIGMA)
    fig, axes = plt.subplots(len(windows), len(models), figsize=(4.2 * len(models), 3.9 * len(windows)))
    for i, w in enumerate(windows):
        for j, m in enumerate(models):
            ax, r, s = axes[i, j], by[w][m], c.plot[(w, m)]
            ok = r["converged"]
            word = verdict_word(ok, r["certificate"]["fraction"]).replace("not converged", "NOT CONVERGED")
            title = (f"{w}, {MODEL_TITLES[m]}\ncertificate {r['certificate']['fraction']:.3f} vs floor "
                     f"{r['floor']['fraction']:.3f}: {word}")
            plot_outcome_map(s.labels, extent=s.extent, ax=ax, legend=False, title=title)
            ax.title.set_fontsize(8)
            if not ok:
                ax.title.set_color("red")
                for sp in ax.spines.values():
                    sp.set_edgecolor("red")
                    sp.set_linewidth(3)
    fig.tight_layout()
    out.save_fig(fig, "l_maps", caption=f"The four windows ({res}² each) in the discrete model (left), the program's "
                 "force law integrated to convergence (middle) and the physical preset (right). Each title gives the "
                 "map's convergence certificate against its chaos floor; a map below its floor, or whose agreement with "
                 "the 10× tighter map is at chance, is framed in red and marked NOT CONVERGED; one above its floor but with a "
                 f"certificate below {CONVERGED_MIN:g} is marked statistics only.")

    fig, axes = plt.subplots(1, len(windows), figsize=(4.2 * len(windows), 3.8), sharey=True)
    for ax, w in zip(axes, windows):
        for k, m in enumerate(models):
            r = by[w][m]
            f = np.asarray(r["pert_f"], dtype=float)
            n = r["pert_n"]
            okf = f > 0
            eps = np.asarray(r["pert_eps_rel"])
            err = np.sqrt(np.maximum(f * (1 - f), 1e-12) / n)  # binomial stderr of each f(ε)
            ax.errorbar(eps[okf], f[okf], yerr=err[okf], fmt="o-", ms=3, capsize=2, color=f"C{k}",
                        label=f"{m} α={fmt(r.get('alpha_pert'), '.2f')}")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("ε / window width")
        ax.set_title(w)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("f(ε): pairs with different outcomes")
    fig.tight_layout()
    out.save_fig(fig, "l_uncertainty", caption="Fraction of uncertain random pairs f(ε) per window and model "
                 "(binomial 1-stderr bars); the slope is the uncertainty exponent α.")

    fig, ax = plt.subplots(figsize=(8, 3.8))
    x = np.arange(len(windows))
    for k, m in enumerate(models):
        for key, mk, dx in (("alpha_pert", "o", -0.2), ("alpha", "s", 0.05)):
            err = "alpha_pert_stderr" if key == "alpha_pert" else "alpha_block_stderr"
            ax.errorbar(x + dx + 0.06 * k, [by[w][m].get(key) or np.nan for w in windows],
                        yerr=[by[w][m].get(err) or 0 for w in windows], fmt=mk, color=f"C{k}", capsize=3,
                        mfc="none" if key == "alpha" else None,
                        label=f"{m}, {'perturbation' if key == 'alpha_pert' else 'boxes'}")
    ax.set_xticks(x, windows)
    ax.set_ylabel("uncertainty exponent α")
    ax.legend(fontsize=7, ncol=3)
    ax.set_title("α by perturbation (filled) and boxes (open), 1-stderr bars")
    fig.tight_layout()
    out.save_fig(fig, "l_alpha", caption="The uncertainty exponent per window and model.")

    for w in windows:
        out.tables[f"window_{w}"] = window_table(by[w], models, sigma)
    out.tables["changes"] = changes_text(by, windows, sigma)
    out.tables.update({f"answer_{k}": v for k, v in answers(by, c.results["summary"], windows, sigma).items()})
    out.tables["certificates"] = md_table([{
        "w": w, "m": m, "integ": _numerics(by[w][m]), "cert": _cert_text(by[w][m]),
        "conv": verdict_text(by[w][m])} for w in windows for m in models], [
        ("w", "window", ""), ("m", "model", ""), ("integ", "integrator", ""),
        ("cert", "certificate [95 % CI], Cohen's κ / chaos floor [95 % CI]", ""), ("conv", "converged", "")])
