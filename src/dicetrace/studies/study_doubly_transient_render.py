"""Study n's figures and tables (:mod:`dicetrace.studies.study_doubly_transient`): local slopes with ε_c, hazards, the
two hypotheses."""

from __future__ import annotations

import math

import numpy as np

from dicetrace.studies.context import Computed, Output
from dicetrace.studies.text import fmt, md_table, pm


def _e(v, spec=".2g"):
    return fmt(v, spec)


def _arr(values) -> np.ndarray:
    """A list from the results (None where a value is missing) as floats (nan)."""
    return np.array([np.nan if v is None else v for v in values], dtype=float)


def _slopes_figure(rows, out: Output, tol: float, floor_tol: float) -> None:
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing

    fig, (a0, a1) = plt.subplots(1, 2, figsize=(12, 4.5))
    for k, r in enumerate(rows):
        col = f"C{k}"
        eps, f, cnt = np.array(r["eps"]), _arr(r["f"]), np.array(r["counted"], dtype=bool)
        a0.loglog(eps[cnt], f[cnt], "o-", color=col, label=r["condition"])
        a0.loglog(eps[~cnt & (f > 0)], f[~cnt & (f > 0)], "o", mfc="none", color=col)
        em, s, se = np.array(r["eps_mid"]), _arr(r["slope"]), _arr(r["slope_stderr"])
        both = cnt[:-1] & cnt[1:]
        a1.errorbar(em[both], s[both], yerr=se[both], fmt="o-", color=col, capsize=2, label=r["condition"])
        other = ~both & np.isfinite(s)
        a1.plot(em[other], s[other], "o", mfc="none", color=col)
        if r["eps_c_status"] == "fitted" and r["eps_c"]:
            a1.axvline(r["eps_c"], color=col, ls=":", lw=1)
    a0.set_xlabel("ε (relative IC perturbation)")
    a0.set_ylabel("f(ε): pairs whose outcome differs")
    a0.set_title("f(ε); hollow: not counted (floor or < 10 changes)")
    a0.legend(fontsize=7)
    a1.axhline(1.0, color="k", lw=0.8)
    a1.set_xscale("log")
    a1.set_xlabel("ε (geometric mid-scale)")
    a1.set_ylabel("local slope d ln f / d ln ε")
    a1.set_title("local slopes (bootstrap 1σ); dotted: fitted ε_c")
    fig.tight_layout()
    out.save_fig(fig, "n_slopes", caption="Uncertainty fraction f(ε) and its local slopes for every model; filled points "
                 f"are above the numerical floor (tol {tol:g} against {floor_tol:g}) with at least 10 changed pairs; dotted lines "
                 "mark the crossover ε_c where it falls inside the counted scales.")


def _hazard_figure(rows, out: Output) -> None:
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    for k, r in enumerate(rows):
        col = f"C{k}"
        for key, ls in (("commit", "-"), ("settle", "--")):
            hc = r["hazard"][key]["curve"]
            t = (np.array(hc["t0"]) + np.array(hc["t1"])) / 2
            h, ev = _arr(hc["h"]), np.array(hc["events"])
            ok = ev >= 5
            axes[0].plot(t[ok], h[ok], ls, color=col, label=f"{r['condition']} ({key})" if key == "commit" else None)
        b = r["hazard"]["bounce"]
        axes[1].errorbar(b["n"], b["h"], yerr=b["stderr"], fmt="o-", ms=3, color=col, capsize=2, label=r["condition"])
        eh = r["lambda"]["energy_hazard"]
        e = np.sqrt(np.array(eh["t0"]) * np.array(eh["t1"]))
        h, se, ev = (_arr(eh[x]) for x in ("h", "stderr", "events"))
        ok = ev >= 3
        axes[2].errorbar(e[ok], h[ok], yerr=se[ok], fmt="o-", ms=3, color=col, capsize=2, label=r["condition"])
    edge = rows[0].get("edge_saddle", rows[0]["edge_rate"]["rate"])
    if edge and math.isfinite(edge):
        axes[0].axhline(edge, color="k", lw=0.8, ls=":")
        axes[2].axhline(edge, color="k", lw=0.8, ls=":")
    axes[0].set_xlabel("t / s")
    axes[0].set_ylabel("hazard h(t) / (1/s)")
    axes[0].set_title(f"hazard of committing (solid) and settling (dashed); dotted: {rows[0]['condition']}'s edge saddle")
    axes[0].legend(fontsize=6)
    axes[1].set_xlabel("landings before the commit, n")
    axes[1].set_ylabel("P(commit at landing n | reached n)")
    axes[1].set_title("hazard per bounce")
    axes[2].set_xscale("log")
    axes[2].set_yscale("log")
    axes[2].set_xlabel("energy above rest / energy to stand on an edge")
    axes[2].set_ylabel("commit hazard / (1/s)")
    axes[2].set_title("hazard against energy (traced random throws)")
    for ax in axes:
        ax.title.set_fontsize(8)
    fig.tight_layout()
    out.save_fig(fig, "n_hazard", caption="Hazard of committing to the final face against time, bounce number and energy, "
                 "and of the stop test (settle time) against time; 1σ Poisson/binomial bars.")


def _tests_figure(rows, out: Output) -> None:
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing

    fig, (a0, a1) = plt.subplots(1, 2, figsize=(12, 4.2))
    x = np.arange(len(rows))
    lab = [r["condition"].replace(" ", "\n", 1) for r in rows]
    t = [r["tests"] for r in rows]
    def col(test, key):
        return _arr([v[test][key] for v in t])

    lo, hi = col("edge_settle", "syst_lo"), col("edge_settle", "syst_hi")
    a0.errorbar(x - 0.1, col("edge_settle", "x"), yerr=col("edge_settle", "x_err"), fmt="o", capsize=3,
                label="late settle hazard κ_late (stat)")
    a0.errorbar(x - 0.1, col("edge_settle", "x"), yerr=[lo, hi], fmt="none", elinewidth=6, alpha=0.25,
                label="its tail-start systematic")
    a0.errorbar(x + 0.1, col("edge_settle", "y"), yerr=col("edge_settle", "y_err"), fmt="s", capsize=3,
                label="α_fine · λ_edge")
    a0.plot(x + 0.1, col("edge_settle_alpha1", "y"), "k_", ms=12, label="λ_edge (analytic)")
    a0.set_xticks(x, lab, fontsize=7)
    a0.set_ylabel("rate / (1/s)")
    a0.set_title("edge hypothesis, settle clock: κ_late = α·λ_edge")
    a0.legend(fontsize=7)
    def field(key):
        return _arr([r[key] for r in rows])

    a1.errorbar(x - 0.15, field("alpha_fine"), yerr=field("alpha_fine_stderr"), fmt="o", capsize=3,
                label="α at the finest counted scale")
    a1.errorbar(x, field("beta"), yerr=field("beta_stderr"), fmt="^", capsize=3, label="β (slope above ε_c)")
    a1.errorbar(x + 0.15, field("kappa_over_lambda1"), yerr=field("kappa_over_lambda1_stderr"), fmt="s", capsize=3,
                label="κ_mid / λ₁")
    a1.axhline(1.0, color="k", lw=0.8)
    a1.set_xticks(x, lab, fontsize=7)
    a1.set_ylabel("exponent")
    a1.set_title("α → 1 (edge) against α = κ/λ₁ (chaotic saddle)")
    a1.legend(fontsize=7)
    fig.tight_layout()
    out.save_fig(fig, "n_tests", caption="The two hypotheses per model, 1σ bars; left: the late settle hazard (past the "
                 "97 % quantile, with the shift when the tail starts at the 90–99 % quantile instead) against the "
                 "finest counted α times the analytic edge saddle.")


def render(c: Computed, out: Output) -> None:
    rows = c.results["rows"]
    _slopes_figure(rows, out, c.results["tol"], c.results["floor_tol"])
    _hazard_figure(rows, out)
    _tests_figure(rows, out)
    out.tables["slopes"] = md_table([{
        "m": r["condition"], "num": f"{r['integrator']} tol {r['tol']:g}", "n": r["n_pairs"],
        "floor": f"{r['floor_throw_flips']}/{r['floor_throws']} (bound {r['floor_bound']:.1e})",
        "emin": _e(r["eps_smallest_counted"]), "af": pm(r["alpha_fine"], r["alpha_fine_stderr"], ".2f"),
        "afe": _e(r["alpha_fine_eps"]),
        "ec": (f"{r['eps_c']:.2g} (±{r['log10_eps_c_stderr']:.2f} dex)" if r["eps_c_status"] == "fitted"
               else {"below": "below the counted scales", "above": "above the counted scales"}.get(
                   r["eps_c_status"], "undetermined")),
        "b": pm(r["beta"], r["beta_stderr"], ".2f"),
    } for r in rows], [("m", "model", ""), ("num", "numerics", ""), ("n", "pairs per scale", ""),
                       ("floor", "floor: throws changed at tol/10", ""), ("emin", "finest counted ε", ""),
                       ("af", "α (finest local slope)", ""), ("afe", "at ε", ""), ("ec", "ε_c", ""),
                       ("b", "β (above ε_c)", "")])
    out.tables["hazard"] = md_table([{
        "m": r["condition"], "med": fmt(r["hazard"]["commit"]["median_s"], ".3f"),
        "w": " → ".join(pm(h, e, ".1f") for h, e in zip(r["hazard"]["commit"]["windows"]["h"],
                                                          r["hazard"]["commit"]["windows"]["stderr"])),
        "ws": " → ".join(pm(h, e, ".1f") for h, e in zip(r["hazard"]["settle"]["windows"]["h"],
                                                           r["hazard"]["settle"]["windows"]["stderr"])),
        "z": fmt(r["hazard"]["commit"]["late_minus_first"]["z"], ".1f"),
        "km": pm(r["hazard"]["commit"]["kappa_mid"], r["hazard"]["commit"]["kappa_mid_stderr"], ".2f"),
        "l1": pm(r["lambda"]["survivors"]["mean"], r["lambda"]["survivors"]["stderr"], ".2f"),
        "la": pm(r["lambda"]["all"]["mean"], r["lambda"]["all"]["stderr"], ".2f"),
        "kl": pm(r["kappa_over_lambda1"], r["kappa_over_lambda1_stderr"], ".2f"),
        "shape": r["hazard_shape"]["commit"]["shape"] if "hazard_shape" in r else "–",
        "sshape": r["hazard_shape"]["settle"]["shape"] if "hazard_shape" in r else "–",
        "dip": fmt(r["hazard_shape"]["commit"]["min_step_z"], ".1f") if "hazard_shape" in r else "–",
        "edge": pm(r["edge_rate"]["rate"], r["edge_rate"]["stderr"], ".2f"),
        "saddle": fmt(r.get("edge_saddle"), ".2f"),
    } for r in rows], [("m", "model", ""), ("med", "median commit (s)", ""),
                       ("w", "commit hazard, quantile windows 50-75-90-97-100 % (1/s)", ""),
                       ("ws", "settle hazard, same windows (1/s)", ""), ("z", "rise, last vs first (z)", ""),
                       ("shape", "commit hazard's shape", ""), ("dip", "largest fall between windows (z)", ""),
                       ("sshape", "settle hazard's shape", ""),
                       ("km", "κ_mid (1/s)", ""), ("l1", "λ₁ survivors (1/s)", ""), ("la", "λ all throws (1/s)", ""),
                       ("kl", "κ_mid/λ₁", ""), ("saddle", "edge saddle, analytic (1/s)", ""),
                       ("edge", "edge-release rate (1/s)", "")])

    def verdict(v):
        return f"{v['verdict']} (z = {fmt(v['z'], '.1f')})"

    def settle_test(v):
        return (f"{pm(v['x'], v['x_err'], '.1f')} (tail +{fmt(v['syst_hi'], '.1f')}/−{fmt(v['syst_lo'], '.1f')}) vs "
                f"{pm(v['y'], v['y_err'], '.1f')}: {v['verdict']} (z = {fmt(v['z'], '.1f')}; stat alone "
                f"{fmt(v['z_stat'], '.1f')})")

    out.tables["tests"] = md_table([{
        "m": r["condition"],
        "es": settle_test(r["tests"]["edge_settle"]),
        "e1": f"{r['tests']['edge_settle_alpha1']['verdict']} (z = {fmt(r['tests']['edge_settle_alpha1']['z'], '.1f')})",
        "ea": verdict(r["tests"]["edge_alpha_fine"]), "sb": verdict(r["tests"]["saddle_beta"]),
        "sa": verdict(r["tests"]["saddle_alpha_fine"]),
    } for r in rows], [("m", "model", ""), ("es", "edge: κ_late (settle) vs α_fine·λ_edge (1/s)", ""),
                       ("e1", "κ_late (settle) vs λ_edge", ""), ("ea", "edge: α_fine = 1", ""),
                       ("sb", "saddle: β = κ_mid/λ₁", ""), ("sa", "saddle: α_fine = κ_mid/λ₁", "")])
    out.tables["tails"] = md_table([{
        "m": r["condition"], "clock": key,
        "v": pm(r["tail"][key]["value"], r["tail"][key]["stat"], ".1f"),
        "by": " / ".join(fmt(v, ".1f") for v in r["tail"][key]["values"]),
        "syst": f"+{fmt(r['tail'][key]['syst_hi'], '.1f')} / −{fmt(r['tail'][key]['syst_lo'], '.1f')}",
        "dom": "yes" if r["tail"][key]["syst_dominates"] else "no",
    } for r in rows if "tail" in r for key in ("settle", "commit")], [
        ("m", "model", ""), ("clock", "clock", ""), ("v", "κ_late past the 97 % quantile (1/s)", ""),
        ("by", "past the 99 / 97 / 95 / 90 % quantile (1/s)", ""), ("syst", "tail-start systematic (+ / −)", ""),
        ("dom", "systematic exceeds statistical", "")])
    diag = [r for r in rows if r.get("release_diagnosis")]
    if diag:
        d = diag[0]["release_diagnosis"]
        out.tables["release"] = md_table([{
            "dt": f"{x['dt_s'] * 1e3:g} ms", "t0": f"{x['tilt0']:g}", "rate": pm(x.get("rate"), x.get("stderr"), ".2f"),
            "from": fmt(x["fit_range"][0] * 1e3, ".1f") if "fit_range" in x else "–",
            "tilt": fmt(x.get("tilt_at_0_1_s"), ".2e"),
            "late": " / ".join(fmt(y["rate"], ".2f") for y in x.get("late", [])),
        } for x in d["rows"]], [("dt", "step", ""), ("t0", "start tilt (rad)", ""),
                                ("rate", "rate fitted from 10× the start tilt (1/s)", ""),
                                ("from", "that fit starts at (ms)", ""), ("tilt", "tilt at 0.1 s (rad)", ""),
                                ("late", "fitted from 0.1 / 0.15 / 0.2 s (1/s)", "")])
