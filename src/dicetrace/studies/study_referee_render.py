"""Figures and tables of study k (referee), from :func:`dicetrace.studies.study_referee.compute`'s numbers."""

from __future__ import annotations

import numpy as np

from dicetrace.studies.context import Computed, Output
from dicetrace.studies.text import fmt, md_table, pm


def _vertices(R: dict, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    V = R["vertices"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for k, r in enumerate(V["controls"] + [r for r in V["rows"] if r["model"] == "discrete"][:1]):
        b = np.asarray(r["box_sizes"], float)
        for key, ls in (("meet3", "o-"), ("any3", "x--")):
            n = np.asarray(r[key], float)
            ok = n > 0
            if ok.any():
                axes[0].loglog(b[ok], n[ok], ls, color=f"C{k}", ms=4, label=f"{r['map']}: {key}")
    axes[0].set_xlabel("box side b (grid intervals)")
    axes[0].set_ylabel("boxes N(b)")
    axes[0].set_title("controls (and home, discrete)", fontsize=9)
    axes[0].legend(fontsize=6)
    for k, r in enumerate(V["rows"]):
        b = np.asarray(r["box_sizes"], float)
        n = np.asarray(r["meet3"], float)
        ok = n > 0
        if ok.any():
            axes[1].loglog(b[ok], n[ok], "o-" if r["model"] == "discrete" else "s:", ms=3,
                           label=f"{r['map']} ({r['model']})")
    axes[1].set_xlabel("box side b (grid intervals)")
    axes[1].set_ylabel("boxes where three outcomes meet")
    axes[1].set_title("the program's vertex-hunt chain", fontsize=9)
    axes[1].legend(fontsize=6)
    fig.tight_layout()
    out.save_fig(fig, "k_vertices", caption="Triple-junction box counts. Left: the controls — three sectors (one "
                 "triple point: N(b) = 1 at every scale) and a strip (three outcomes, two parallel borders, no vertex: "
                 "boxes holding three outcomes appear once b exceeds the strip, boxes where three meet never). Right: "
                 "the die's windows, boxes where three outcomes meet.")
    cols = [("map", "map", ""), ("model", "model", ""), ("res", "grid", "d"), ("sizes", "box sizes", ""),
            ("meet", "boxes where 3 meet, N(b)", ""), ("dm", "dimension (meet)", ""),
            ("da", "dimension (≥ 3 outcomes, old count)", "")]

    def row(r):
        return {"map": r["map"], "model": r.get("model", "control"), "res": r["res"],
                "sizes": f"{int(r['box_sizes'][0])}…{int(r['box_sizes'][-1])} ({len(r['box_sizes'])})",
                "meet": " ".join(fmt(v, ".3g") for v in r["meet3"]),
                "dm": (pm(r["dim_meet3"], r["dim_meet3_stderr"], ".2f") + (" (clamped)" if r["clamped"] else ""))
                if r["dim_meet3"] is not None else "no junction",
                "da": pm(r["dim_any3"], r["dim_any3_stderr"], ".2f") if r["dim_any3"] is not None else "–"}

    out.tables["vertices"] = md_table([row(r) for r in V["controls"] + V["rows"]], cols)


def _delta(v, deltas) -> str:
    """An equivalent δ: a number, or the study's text for one outside the measured range."""
    return v if isinstance(v, str) else fmt(v, ".2g")


def _floor(R: dict, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    F = R["floor"]
    fig, axes = plt.subplots(1, len(F), figsize=(5.5 * len(F), 4.2), squeeze=False)
    rows = []
    for ax, (w, d) in zip(axes[0], F.items()):
        de = np.array([f["delta"] for f in d["floor"]])
        fr = np.array([f["fraction"] for f in d["floor"]])
        lo = np.array([f["ci"][0] for f in d["floor"]])
        hi = np.array([f["ci"][1] for f in d["floor"]])
        ka = np.array([f["kappa"] for f in d["floor"]])
        ax.errorbar(de, fr, yerr=[fr - lo, hi - fr], fmt="o-", capsize=3, label="chaos floor (converged)")
        ax.plot(de, ka, "s:", label="Cohen's κ of the floor")
        dv = d["discrete_vs_converged"]
        ax.axhspan(dv["ci"][0], dv["ci"][1], color="C3", alpha=0.3, label=f"discrete vs converged {dv['fraction']:.3f}")
        ax.set_xscale("log")
        ax.set_ylim(-0.05, 1.05)
        ax.set_xlabel("relative IC perturbation δ")
        ax.set_ylabel("agreement")
        ax.set_title(f"{w}: {d['n']} ICs", fontsize=9)
        ax.legend(fontsize=7)
        for f in d["floor"]:
            rows.append({"w": w, "d": f["delta"], "a": f"{f['fraction']:.3f} [{f['ci'][0]:.3f}, {f['ci'][1]:.3f}]",
                         "k": pm(f["kappa"], f["kappa_stderr"], ".3f")})
        rows.append({"w": w, "d": "discrete (1 ms)", "a": f"{dv['fraction']:.3f} [{dv['ci'][0]:.3f}, {dv['ci'][1]:.3f}]",
                     "k": pm(dv["kappa"], dv["kappa_stderr"], ".3f"),
                     "eq": f"{_delta(d['equivalent_delta'], d['deltas'])} [{_delta(d['equivalent_delta_ci'][0], d['deltas'])}, "
                           f"{_delta(d['equivalent_delta_ci'][1], d['deltas'])}]"})
    fig.tight_layout()
    out.save_fig(fig, "k_floor", caption="Chaos floor of the converged model (agreement with itself under a relative "
                 "IC perturbation δ, 95 % Wilson intervals; Cohen's κ dotted) up to δ = 1e-2, and the discrete "
                 "model's agreement with the converged one (band: its Wilson interval).")
    out.tables["floor"] = md_table(rows, [("w", "window", ""), ("d", "δ", ""), ("a", "agreement [95 % CI]", ""),
                                          ("k", "Cohen's κ", ""), ("eq", "equivalent δ [CI]", "")])


def _alpha(R: dict, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    A = R["alpha"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    rows = []
    for k, (key, r) in enumerate(A.items()):
        e, f = np.asarray(r["eps_rel"]), np.asarray(r["f"], float)
        ok = f > 0
        axes[0].loglog(e[ok], f[ok], "o-", color=f"C{k}", ms=3, label=key)
        if r.get("alpha") is not None:
            axes[1].errorbar(r["local_eps_rel"], r["local_slope"], yerr=r["local_stderr"], fmt="o-", color=f"C{k}",
                             ms=3, capsize=2, label=key)
            axes[0].axvline(r["eps_c_rel"], color=f"C{k}", lw=0.8, ls=":")
        rows.append({"k": key, "all": pm(r["alpha_all"], r["alpha_all_stderr"], ".2f"),
                     "un": pm(r.get("alpha"), r.get("alpha_stderr"), ".2f"),
                     "sm": pm(r.get("alpha_smallest"), r.get("alpha_smallest_stderr"), ".2f"),
                     "ec": fmt(r.get("eps_c_rel"), ".2g"), "fs": r["f_sat"], "n": r["n"]})
    axes[0].set_xlabel("ε / window width")
    axes[0].set_ylabel("f(ε), fraction of uncertain pairs")
    axes[0].legend(fontsize=7)
    axes[0].set_title("f(ε); dotted: crossover ε_c", fontsize=9)
    axes[1].set_xscale("log")
    axes[1].set_ylim(-0.2, 1.6)
    axes[1].axhline(1, color="k", lw=0.5)
    axes[1].set_xlabel("ε / window width")
    axes[1].set_ylabel("local slope d log f / d log ε")
    if axes[1].get_legend_handles_labels()[0]:
        axes[1].legend(fontsize=7)
    else:  # no window has an unsaturated range of ε (the quick run's small grids)
        axes[1].text(0.5, 0.5, "no window has a range of ε\nbelow saturation to fit", ha="center", va="center",
                     transform=axes[1].transAxes, fontsize=9)
    fig.tight_layout()
    out.save_fig(fig, "k_alpha", caption="Uncertain fraction f(ε) by perturbation (left) and its local slope with "
                 "binomial 1σ bars (right); a smooth border has slope 1, saturation slope 0.")
    out.tables["alpha"] = md_table(rows, [("k", "window/model", ""), ("n", "points", "d"),
                                          ("all", "α all ε (old fit)", ""), ("un", "α unsaturated", ""),
                                          ("sm", "local slope, smallest ε", ""), ("ec", "crossover ε_c / width", ""),
                                          ("fs", "f_sat", ".3f")])


def _lambda(R: dict, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    L = R["lambda"]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for k, (model, r) in enumerate(L["fits"].items()):
        lam = np.asarray(r.get("all", []), float)
        lam = lam[np.isfinite(lam) & (lam > 0) & (lam < 100)]
        if len(lam):
            ax.hist(lam, bins=np.linspace(0, 80, 41), alpha=0.5, color=f"C{k}", label=f"{model}: all {r['n']} fits")
    ax.axvline(L["analytic_fixed_pivot"], color="k", lw=1, label="edge saddle, held pivot (analytic)")
    ax.axvline(L["analytic_free_pivot"], color="k", lw=1, ls="--", label="frictionless floor (analytic)")
    out.save_plot(fig, ax, "k_lambda", xlabel="λ from settle-time divergence (1/s)", ylabel="fits",
                  title="Every border fit, no selection", caption="Divergence rates of every border fit (both sides "
                  "of each border) against the edge saddle's rigid-body rate.")
    out.tables["lambda_release"] = md_table([
        {"m": r["model"], "t": r["tilt0"], "r": pm(r.get("rate"), r.get("stderr"), ".2f") if r.get("rate") else
         r.get("error", "–")} for r in L["releases"]],
        [("m", "model", ""), ("t", "released at tilt (rad)", ".0e"), ("r", "λ of the release (1/s)", "")])
    out.tables["lambda_jacobian"] = md_table([
        {"m": r["model"], "r": r["rate"], "f": r["rate_fine"], "mu": ", ".join(f"{v:.3g}" for v in r["abs_eigenvalues"])}
        for r in L.get("jacobian", [])],
        [("m", "model", ""), ("r", "λ = ln(largest modulus)/T, step h (1/s)", ".3f"), ("f", "the same at h/100", ".3f"),
         ("mu", "moduli of the eigenvalues of the 0.1 s map", "")])
    out.tables["lambda_fits"] = md_table([
        {"m": m, "n": r.get("n"), "b": r["n_borders"], "u": r["n_sides_unfit"],
         "med": pm(r.get("median"), r.get("total"), ".2f"), "st": fmt(r.get("stat"), ".2f"),
         "sy": fmt(r.get("syst"), ".2f"), "iqr": f"{fmt(r.get('q25'), '.1f')}–{fmt(r.get('q75'), '.1f')}",
         "nf": f"{fmt(r.get('median_near'), '.1f')} / {fmt(r.get('median_far'), '.1f')}"}
        for m, r in L["fits"].items()],
        [("m", "model", ""), ("b", "borders", "d"), ("n", "fits", "d"), ("u", "sides without a fit", "d"),
         ("med", "median λ ± total (1/s)", ""), ("st", "stat", ""), ("sy", "syst", ""), ("iqr", "IQR", ""),
         ("nf", "median near / far half of d", "")])


def _onecell(R: dict, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    O = R["onecell"]
    fig, ax = plt.subplots(figsize=(6, 4))
    n = [r["res"][0] for r in O["series"]]
    j = np.array([r["join_fraction"] for r in O["series"]])
    m = np.array([r["n_cells"] for r in O["series"]], float)
    se = np.sqrt(j * (1 - j) / np.maximum(m, 1))
    ax.errorbar(n, j, yerr=se, fmt="o-", capsize=3)
    out.save_plot(fig, ax, "k_onecell", xlabel="stack nodes per x, y axis (red sea, z depth 0.3)",
                  ylabel="fraction of 2-D cells joined through z", legend=False,
                  title=f"3-D join fraction against resolution: {O['verdict']}",
                  caption="Fraction of the red sea's 2-D cells (≥ 5 nodes) that share a 3-D cell with another 2-D "
                  "cell of the slice, against the resolution of the stack (binomial 1σ bars).")
    out.tables["onecell_null"] = md_table([
        {"p": f"({t['period'][0]:.3f}, {t['period'][1]:.3f})", "o": t["overlap"], "nm": t["null_median"],
         "n9": t["null_q90"], "pv": t["p_value"], "nn": t["n_null"]} for t in O["tests"]],
        [("p", "texture period (x, y)", ""), ("o", "median overlap", ".3f"), ("nm", "null median", ".3f"),
         ("n9", "null 90 %", ".3f"), ("pv", "p-value", ".3f"), ("nn", "null shifts", "d")])
    out.tables["onecell_series"] = md_table([
        {"g": "×".join(str(v) for v in r["res"]), "j": r["join_fraction"], "n": r["n_cells"]} for r in O["series"]],
        [("g", "stack", ""), ("n", "2-D cells ≥ 5 nodes", "d"), ("j", "joined through z", ".3f")])


def _entropy(R: dict, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    E = R["entropy"]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for k, r in enumerate(E["rows"]):
        c = np.asarray(r["counts"], float)
        ok = c > 0
        ax.semilogy(np.arange(1, len(c) + 1)[ok], c[ok], "o-" if r["model"] == "converged" else "x:", ms=3,
                    color=f"C{k}", label=f"{r['model']}, sets ≥ {r['min_steps']} ms: h = {fmt(r['h'], '.2f')}")
    ax.axhline(0.1 * E["n"], color="k", lw=0.6, ls="--")
    out.save_plot(fig, ax, "k_entropy", xlabel="prefix length n (contact sets)", ylabel="distinct prefixes N(n)",
                  title=f"Contact-sequence prefixes, {E['n']} throws of the {E['window']} window",
                  caption="Distinct prefixes against their length; the fit uses N(n) below 10 % of the sample "
                  "(dashed line).")
    out.tables["entropy"] = md_table([
        {"m": r["model"], "s": r["min_steps"], "h": pm(r["h"], r["h_stderr"], ".3f"),
         "r": f"{r['n_range'][0]}–{r['n_range'][1]}", "hh": fmt(r["h_half"], ".3f"), "hq": fmt(r["h_quarter"], ".3f"),
         "L": r["median_length"], "d": r["distinct_full"], "n": r["n_sequences"]} for r in E["rows"]],
        [("m", "model", ""), ("s", "sets kept ≥ (steps of 1 ms)", "d"), ("h", "h (nats/set)", ""),
         ("r", "fitted n", ""), ("hh", "h, half sample", ""), ("hq", "h, quarter", ""),
         ("L", "median length (sets)", ".0f"), ("d", "distinct whole sequences", "d"), ("n", "throws", "d")])


def _stiffness(R: dict, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    S = R["stiffness"]
    ks = np.array([r["k"] for r in S["rows"]])
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for f in range(1, 7):
        v = np.array([r["faces"][str(f)] for r in S["rows"]])
        axes[0].errorbar(ks * (1 + 0.03 * (f - 3.5)), v[:, 0], yerr=[v[:, 0] - v[:, 1], v[:, 2] - v[:, 0]],
                         fmt="o-", capsize=2, ms=3, label=f"face {f}")
    axes[0].set_xscale("log")
    axes[0].set_xlabel("k (1/s²)")
    axes[0].set_ylabel("fraction (95 % Wilson)")
    axes[0].legend(fontsize=6)
    axes[1].errorbar(ks, [r["settle_mean_s"] for r in S["rows"]], yerr=[r["settle_stderr_s"] for r in S["rows"]],
                     fmt="o-", capsize=3, label="mean settle time (s)")
    ax2 = axes[1].twinx()
    ax2.loglog(ks, [r["pen_median_cm"] for r in S["rows"]], "s--", color="C1", label="median peak penetration (cm)")
    ax2.loglog(ks, [r["pen_max_cm"] for r in S["rows"]], "^:", color="C1", label="max peak penetration (cm)")
    axes[1].set_xscale("log")
    axes[1].set_xlabel("k (1/s²)")
    axes[1].set_ylabel("settle time (s)")
    ax2.set_ylabel("peak penetration (cm)")
    ax2.legend(fontsize=6, loc="lower left")
    a = [r["alpha"] if r["alpha"] is not None else np.nan for r in S["rows"]]
    ae = [r["alpha_stderr"] if r["alpha_stderr"] is not None else np.nan for r in S["rows"]]
    axes[2].errorbar(ks, a, yerr=ae, fmt="o-", capsize=3)
    axes[2].set_xscale("log")
    axes[2].set_xlabel("k (1/s²)")
    axes[2].set_ylabel("α (unsaturated range)")
    fig.tight_layout()
    out.save_fig(fig, "k_stiffness", caption=f"The physical preset's {S['window']} window against the ground "
                 "stiffness: face fractions, settle time and peak penetration, and α.")
    out.tables["stiffness"] = md_table([
        {"k": f"{r['k']:.1e}", "f": " ".join(f"{r['faces'][str(f)][0]:.3f}" for f in range(1, 7)),
         "t": pm(r["settle_mean_s"], r["settle_stderr_s"], ".3f"), "p": f"{r['pen_median_cm']:.4f} / {r['pen_max_cm']:.4f}",
         "a": pm(r["alpha"], r["alpha_stderr"], ".2f"), "u": r["unsettled"],
         "aa": pm(r["alpha_all"], r["alpha_all_stderr"], ".2f"),
         "ag": f"{r['agreement_with_softest']['fraction']:.3f} (κ {r['agreement_with_softest']['kappa']:.2f})"}
        for r in S["rows"]],
        [("k", "k (1/s²)", ""), ("f", "faces 1–6", ""), ("u", "unsettled", "d"), ("t", "mean settle time (s)", ""),
         ("p", "peak penetration median / max (cm)", ""), ("a", "α unsaturated", ""), ("aa", "α all ε", ""),
         ("ag", "same outcome as k = 5·10⁵ (κ)", "")])


def render(c: Computed, out: Output) -> None:
    R = c.results
    _vertices(R, out)
    _floor(R, out)
    _alpha(R, out)
    _lambda(R, out)
    _onecell(R, out)
    _entropy(R, out)
    _stiffness(R, out)
