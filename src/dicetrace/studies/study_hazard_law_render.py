"""Study r's figure and tables (:mod:`dicetrace.studies.study_hazard_law`): the settle hazard against α(ε(t))·λ_edge,
the nested f(ε) with its local slopes, and the settle clock."""

from __future__ import annotations

import numpy as np

from dicetrace.studies.context import Computed, Output
from dicetrace.studies.text import fmt, md_table, pm


def _arr(values) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], dtype=float)


def _figure(rows, out: Output) -> None:
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing

    fig, axes = plt.subplots(1, 4, figsize=(19, 4.6))
    for k, r in enumerate(rows):
        col = f"C{k}"
        ws = [w for w in r["windows"] if w["tail"]]
        tm = np.array([(w["t0"] + w["t1"]) / 2 for w in ws])
        h, he = _arr([w["h"] for w in ws]), _arr([w["h_err"] for w in ws])
        axes[0].errorbar(tm, h, yerr=he, fmt="o", color=col, capsize=2, label=f"{r['model']}: κ_settle")
        p, pe = _arr([w["pred"] for w in ws]), _arr([w["pred_err"] for w in ws])
        ok = np.isfinite(p)
        axes[0].errorbar(tm[ok] + 0.004, p[ok], yerr=np.nan_to_num(pe[ok]), fmt="s", mfc="none", color=col, capsize=2,
                         label=f"{r['model']}: α(ε(t))·λ_edge")
        axes[0].axhline(r["edge_saddle"], color=col, ls=":", lw=1)
        f = r["f"]
        eps, fv, cnt = np.array(f["eps"]), _arr(f["f"]), np.array(f["counted"], dtype=bool)
        axes[1].loglog(eps[cnt], fv[cnt], "o-", color=col, label=r["model"])
        other = ~cnt & (fv > 0)
        axes[1].loglog(eps[other], fv[other], "o", mfc="none", color=col)
        em, s, se = np.array(f["eps_mid"]), _arr(f["slope"]), _arr(f["slope_stderr"])
        both = cnt[:-1] & cnt[1:]
        axes[2].errorbar(em[both], s[both], yerr=np.nan_to_num(se[both]), fmt="o-", color=col, capsize=2,
                         label=r["model"])
        rest = ~both & np.isfinite(s)
        axes[2].plot(em[rest], s[rest], "o", mfc="none", color=col)
        tmn, tse, dep = _arr(f["t_mean"]), _arr(f["t_sem"]), _arr(f.get("depth", [0.0] * len(eps)))
        axes[3].errorbar(eps[cnt], tmn[cnt] - dep[cnt] / r["edge_saddle"], yerr=np.nan_to_num(tse[cnt]), fmt="o",
                         color=col, capsize=2, label=r["model"])
        if r.get("t0") is not None:
            xx = np.geomspace(eps[cnt].min() if cnt.any() else eps.min(), eps.max(), 50)
            axes[3].plot(xx, r["t0"] - np.log(xx) / r["edge_saddle"], "-", color=col, lw=0.8)
    axes[0].set_xlabel("t / s (window mid)")
    axes[0].set_ylabel("hazard / (1/s)")
    axes[0].set_title("settle hazard (filled) and the law's prediction (open); dotted: λ_edge", fontsize=9)
    axes[0].legend(fontsize=6)
    axes[1].set_xlabel("ε (relative IC distance)")
    axes[1].set_ylabel("f(ε)")
    axes[1].set_title("f(ε), nested pairs; hollow: not counted", fontsize=9)
    axes[1].legend(fontsize=7)
    axes[2].axhline(1.0, color="k", lw=0.8)
    axes[2].set_xscale("log")
    axes[2].set_xlabel("ε (geometric mid-scale)")
    axes[2].set_ylabel("local slope α")
    axes[2].set_title("local slopes of f (bootstrap 1σ)", fontsize=9)
    axes[3].set_xscale("log")
    axes[3].set_xlabel("ε")
    axes[3].set_ylabel("mean settle time of the bases changed at ε, less D/λ_edge / s")
    axes[3].set_title("the settle clock; line: T0 − ln ε/λ_edge", fontsize=9)
    axes[3].legend(fontsize=7)
    fig.tight_layout()
    out.save_fig(fig, "r_hazard_law", caption="The hazard law per model: the settle hazard in windows past the 90 % "
                 "quantile of the settle time against α(ε(t))·λ_edge (1σ bars); f(ε) from nested pairs (filled: "
                 "counted, above the floor at tol/10 with at least 10 changed pairs) and its local slopes; the settle "
                 "clock, the mean settle time of the bases whose pair changed at ε less their mean depth below ε "
                 "(D, read off f) over λ_edge, with the line T0 − ln ε/λ_edge.")


def _eps_range(w) -> str:
    return f"{fmt(w['eps_hi'], '.1e')} → {fmt(w['eps_lo'], '.1e')}"


def render(c: Computed, out: Output) -> None:
    r = c.results
    rows = r["rows"]
    _figure(rows, out)
    num = []
    for row in rows:
        f, cert, q = row["f"], row["certificate"], row["settle_quantiles"]
        leak = f["leak"]
        num.append({
            "model": row["model"], "numerics": f"{row['integrator']} tol {row['tol']:g}; nested pairs {row['nested_tol']:g}",
            "n": row["n"], "unsettled": row["unsettled"],
            "quant": " / ".join(fmt(q[k], ".3f") for k in ("0.5", "0.99", "0.999", "0.9997")),
            "scales": f"{fmt(f['eps'][-1], '.1e')} → {fmt(f['eps'][0], '.0e')}",
            "top": f"{f['top_changed']} ({fmt(f['f'][-1], '.3f')})",
            "leak": f"{leak['changed']}/{leak['pairs']} (≤ {fmt(leak['hi95'], '.1e')}; {fmt(leak['share'], '.0%')} "
                    f"of f)",
            "floor": f"{f['floor_throw_flips']}/{f['floor_throws']} throws, {sum(f['floor_flips'])} pairs; top "
                     f"{f['top_floor_flips']}/{f['top_floor_pairs']}",
            "cert": f"{cert['outcome_flips']}/{cert['thrown']}; {fmt(cert['dt_median_s'], '.1e')} / "
                    f"{fmt(cert['dt_q99_s'], '.1e')}",
            "finest": f["finest_counted"],
        })
    out.tables["numerics"] = md_table(num, [
        ("model", "model", ""), ("numerics", "numerics", ""), ("n", "throws", "d"), ("unsettled", "unsettled", "d"),
        ("quant", "settle time at the 50 / 99 / 99.9 / 99.97 % quantile (s)", ""),
        ("scales", "nested scales (top → finest)", ""), ("top", "pairs changed at the top (f)", ""),
        ("leak", "leak: changed at the next scale, not at the top (95 % bound on f)", ""),
        ("floor", "floor of the nested pairs at their tol/10: faces changed", ""), ("finest", "finest counted ε", ".1e"),
        ("cert", "tail at tol/10: faces changed / thrown; settle-time shift median / 99 % (s)", ""),
    ])
    fr = []
    for row in rows:
        f = row["f"]
        for k in range(len(f["eps"]) - 1, -1, -1):
            fr.append({"model": row["model"], "eps": f["eps"][k], "changed": f["changed"][k], "f": f["f"][k],
                       "bound": f["floor_bound"][k], "counted": "yes" if f["counted"][k] else "no",
                       "slope": pm(f["slope"][k - 1], f["slope_stderr"][k - 1], ".2f") if k > 0 else "–",
                       "t": pm(f["t_mean"][k], f["t_sem"][k], ".3f")})
    out.tables["f"] = md_table(fr, [
        ("model", "model", ""), ("eps", "ε", ".1e"), ("changed", "pairs changed", "d"), ("f", "f(ε)", ".2e"),
        ("bound", "floor bound", ".1e"), ("counted", "counted", ""),
        ("slope", "local slope to the next finer scale", ""), ("t", "mean settle time of those bases (s)", ""),
    ])
    lw = []
    for row in rows:
        for w in row["windows"]:
            if not w["tail"]:
                continue
            lw.append({"model": row["model"], "q": f"{100 * w['q0']:g}–{100 * w['q1']:g} %",
                       "t": f"{w['t0']:.3f}–{w['t1']:.3f}", "events": w["events"],
                       "h": pm(w["h"], w["h_err"], ".1f"),
                       "tol": fmt(w["tol_syst"], ".1f"), "eps": _eps_range(w),
                       "alpha": pm(w["alpha"], w["alpha_stderr"], ".2f"),
                       "pred": pm(w["pred"], w["pred_err"], ".1f"),
                       "clock": (f"+{fmt(w['clock_syst_hi'], '.1f')} / −{fmt(w['clock_syst_lo'], '.1f')}"
                                 if w["pred"] is not None else "–"),
                       "z": fmt(w["z"], ".1f"), "verdict": w["verdict"]})
    out.tables["law"] = md_table(lw, [
        ("model", "model", ""), ("q", "window (quantiles)", ""), ("t", "t (s)", ""), ("events", "settled", "d"),
        ("h", "κ_settle (1/s)", ""), ("tol", "tolerance systematic (1/s)", ""), ("eps", "ε(t) on the clock", ""),
        ("alpha", "α over those scales", ""), ("pred", "α·λ_edge (1/s)", ""),
        ("clock", "clock systematic (1/s)", ""), ("z", "z", ""), ("verdict", "verdict", ""),
    ])
    sm = []
    for row in rows:
        v, cs, cc, lv = row["verdict"], row["clock_scan"] or {}, row["clock_check"], row["last_window_vs_edge"] or {}
        sm.append({
            "model": row["model"], "edge": row["edge_saddle"],
            "t0": (f"{fmt(cs.get('value'), '.3f')} ± {fmt(cs.get('stat'), '.3f')} (+{fmt(cs.get('syst_hi'), '.3f')} / "
                   f"−{fmt(cs.get('syst_lo'), '.3f')} range)" if cs else "–"),
            "clock": f"{pm(cc['x'], cc['x_err'], '.1f')} (z = {fmt(cc['z'], '.1f')})",
            "law": f"{v['verdict']} ({v['n_windows']} windows, max |z| = {fmt(v['max_abs_z'], '.1f')}, "
                   f"χ² = {fmt(v['chi2'], '.1f')}, p = {fmt(v['p_value'], '.2g')})",
            "last": f"{pm(lv.get('x'), lv.get('x_err'), '.1f')} (z = {fmt(lv.get('z'), '.1f')})",
            "level": (f"{100 * row['levels_off_from_q']:g} % quantile ({fmt(row['levels_off_from_s'], '.3f')} s)"
                      if row["levels_off_from_q"] is not None else "not reached"),
            "alpha1": fmt(row["alpha_one_below"], ".1e", missing="none counted"),
        })
    out.tables["summary"] = md_table(sm, [
        ("model", "model", ""), ("edge", "λ_edge (1/s)", ".2f"), ("t0", "clock T0 (s)", ""),
        ("clock", "clock's free slope as a rate (1/s), vs λ_edge", ""), ("law", "the law, tail windows", ""),
        ("last", "last window's κ_settle vs λ_edge (1/s)", ""), ("level", "consistent with λ_edge from", ""),
        ("alpha1", "local slopes consistent with 1 below ε", ""),
    ])
