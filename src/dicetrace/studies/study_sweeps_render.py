"""Study q's figures and tables (:mod:`dicetrace.studies.study_sweeps`): ε_c and α against γ and k, hazard
curves, face fractions with block-bootstrap errors, certificates and the Puy and Wada tests."""

from __future__ import annotations

import math

import numpy as np

from dicetrace.studies.context import Computed, Output
from dicetrace.studies.text import fmt, md_table, pm


def _num(v) -> float:
    return math.nan if v is None else float(v)


def series(rows, param: str) -> dict:
    """window -> rows of the sweep of ``param`` ("gamma" or "k"): the conditions where only it moves from the
    preset's (the preset itself included), ordered by its value."""
    base = next((r for r in rows if r["condition"] == "physical"), None)
    other = "k" if param == "gamma" else "gamma"
    out: dict = {}
    for r in rows:
        if base is not None and r[other] != base[other]:
            continue
        out.setdefault(r["window"], []).append(r)
    return {w: sorted(v, key=lambda r: r[param]) for w, v in out.items()}


def _numerics_text(n: dict) -> str:
    if n.get("tol") is None or n["integrator"] == "contact-substep":
        return f"{n['integrator']} dt {n['dt_s']:g} s"
    grow = f" growing {n['tol_growth']:g}/s" if n.get("tol_growth") else " uniform"
    return f"{n['integrator']} tol {n['tol']:g}{grow}"


def _eps_alpha_figure(rows, out: Output) -> None:
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing

    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
    for col, (param, label) in enumerate((("gamma", "γ (s/cm)"), ("k", "k (1/s²)"))):
        drawn = False
        for j, (w, rs) in enumerate(series(rows, param).items()):
            x = np.array([r[param] for r in rs], dtype=float)
            p = [r["pairs"] for r in rs]
            fitted = np.array([q["eps_c_status"] == "fitted" for q in p])
            ec = np.array([_num(q["eps_c"]) for q in p])
            dex = np.array([_num(q["log10_eps_c_stderr"]) for q in p])
            lo, hi = ec * (1 - 10 ** -np.nan_to_num(dex)), ec * (10 ** np.nan_to_num(dex) - 1)
            c = f"C{j}"
            a0 = axes[0, col]
            a0.errorbar(x[fitted], ec[fitted], yerr=[lo[fitted], hi[fitted]], fmt="o-", color=c, capsize=3, label=w)
            bound = np.array([q["eps_c_status"] == "below" for q in p])
            fine = np.array([_num(q["eps_smallest_counted"]) for q in p])
            a0.plot(x[bound], fine[bound], "v", color=c, mfc="none", ms=8)
            drawn |= bool(np.any(np.isfinite(ec[fitted]) & (ec[fitted] > 0)) or np.any(np.isfinite(fine[bound])))
            a1 = axes[1, col]
            af = np.array([_num(q["alpha_fine"]) for q in p])
            se = np.array([_num(q["alpha_fine_stderr"]) for q in p])
            a1.errorbar(x * (1 + 0.03 * (j - 1)), af, yerr=se, fmt="o-", color=c, capsize=3, label=w)
        values = sorted({r[param] for rs in series(rows, param).values() for r in rs})
        for a in axes[:, col]:
            a.set_xscale("log")
            a.set_xlabel(label)
            a.set_xticks(values, [f"{v:g}" for v in values])
            a.minorticks_off()
        if drawn:  # no ε_c fitted nor bounded: nothing to draw on a log axis
            axes[0, col].set_yscale("log")
        else:
            axes[0, col].text(0.5, 0.5, "no ε_c resolved", transform=axes[0, col].transAxes, ha="center")
        axes[0, col].set_ylabel("ε_c (relative IC perturbation)")
        axes[0, col].set_title(f"ε_c against {label.split()[0]}; hollow ▽: below the finest counted ε (bound)",
                               fontsize=8)
        axes[1, col].axhline(1.0, color="k", lw=0.8)
        axes[1, col].set_ylabel("α: finest counted local slope")
        axes[1, col].set_title(f"local α against {label.split()[0]} (bootstrap 1σ)", fontsize=8)
        axes[1, col].legend(fontsize=7)
    fig.tight_layout()
    out.save_fig(fig, "q_eps_alpha", caption="Crossover scale ε_c (fitted, with its bootstrap error in dex; hollow "
                 "triangles: ε_c below the counted scales, drawn at the finest counted ε) and the finest counted "
                 "local slope α of f(ε), against the damping γ (k at the preset's) and the ground stiffness k "
                 "(γ at the preset's), per window; uniform tolerance 1e-10.")


def _per_window(rows, windows, draw, labels: tuple[str, str], out: Output, name: str, caption: str) -> None:
    """One panel per window, titled with it: ``draw(ax, row, k, n)`` for each of its rows (``k``: the index of the
    row's condition, its colour, of ``n``), axes labelled ``labels`` (x, y), a legend; saved as figure ``name``."""
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing

    conds = list(dict.fromkeys(r["condition"] for r in rows))
    fig, axes = plt.subplots(1, len(windows), figsize=(5 * len(windows), 4.2), squeeze=False)
    for ax, w in zip(axes[0], windows):
        for r in rows:
            if r["window"] == w:
                draw(ax, r, conds.index(r["condition"]), len(conds))
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        ax.set_title(w)
        ax.legend(fontsize=6)
    fig.tight_layout()
    out.save_fig(fig, name, caption=caption)


def _hazard_figure(rows, windows, out: Output) -> None:
    def draw(ax, r, k, _n):
        ax.set_yscale("log")
        hz = r["pairs"]["hazard"]
        if hz is None:
            return
        hc = hz["commit"]["curve"]
        t = (np.array(hc["t0"]) + np.array(hc["t1"])) / 2
        h = np.array([_num(v) for v in hc["h"]])
        se = np.array([_num(v) for v in hc["stderr"]])
        ok = np.array(hc["events"]) >= 5
        conv = r["map"]["converged"]
        ax.errorbar(t[ok], h[ok], yerr=se[ok], fmt="o-" if conv else "o--", ms=3, capsize=2, color=f"C{k}",
                    label=r["condition"] + ("" if conv else " (statistics only)"))

    _per_window(rows, windows, draw, ("t / s", "commit hazard h(t) / (1/s)"), out, "q_hazard",
                caption="Hazard of committing to the final face against time, per window and condition "
                "(piecewise-constant maximum likelihood, bins with at least 5 events, 1σ Poisson bars); uniform "
                "tolerance 1e-10; dashed: the window's map is statistics only (certificate < 0.99).")


def _faces_figure(rows, windows, out: Output) -> None:
    def draw(ax, r, k, n):
        f = r["map"]["faces"]["faces"]
        x = np.arange(1, 7) + 0.12 * (k - (n - 1) / 2)
        ax.errorbar(x, [f[str(i)]["fraction"] for i in range(1, 7)], yerr=[f[str(i)]["stderr"] for i in range(1, 7)],
                    fmt="o" if r["map"]["converged"] else "s", mfc=None if r["map"]["converged"] else "none",
                    color=f"C{k}", capsize=2, label=f"{r['condition']} ({r['map']['status']})")
        ax.axhline(1 / 6, color="k", lw=0.6, ls=":")
        ax.set_xticks(range(1, 7))

    _per_window(rows, windows, draw, ("face up", "fraction of the map"), out, "q_faces",
                caption="Face fractions of each map with moving-block bootstrap errors (1σ, the larger of "
                "blocks of 1/8 and 1/4 of the map's side); filled: converged map (certificate ≥ 0.99), hollow: "
                "statistics only; dotted: 1/6.")


def render(c: Computed, out: Output) -> None:
    r = c.results
    rows, windows = r["rows"], r["windows"]
    _eps_alpha_figure(rows, out)
    _hazard_figure(rows, windows, out)
    _faces_figure(rows, windows, out)

    def cert(m):
        a = m["certificate"]
        return f"{a['fraction']:.3f} [{a['ci'][0]:.3f}, {a['ci'][1]:.3f}] of {a['n']}"

    def puy(m):
        p = m["puy"]
        if p.get("error"):
            return "undetermined (too little boundary)"
        return f"{pm(p['Sbb'], p['Sbb_stderr'], '.3f')} vs {p['smooth']:.3f}: {p['verdict']}"

    def wada(m):
        wd = m["wada"]
        if wd.get("error"):
            return "fewer than 3 faces"
        return (f"r = {wd['r_wada']}" if wd["wada"] else "no") + f" (far at r=5: {wd['far_r5']:.3f})"

    out.tables["maps"] = md_table([{
        "c": x["condition"], "w": x["window"], "num": f"{x['map']['res']}², {_numerics_text(x['map']['numerics'])}",
        "cert": cert(x["map"]),
        "chk": f"{x['map']['reference_check']['fraction']:.2f} of {x['map']['reference_check']['n']}",
        "st": x["map"]["status"], "puy": puy(x["map"]), "wada": wada(x["map"]),
    } for x in rows], [("c", "condition", ""), ("w", "window", ""), ("num", "map", ""),
                       ("cert", "certificate: agreement with the reference (95 %)", ""),
                       ("chk", "reference vs third integrator", ""), ("st", "map is", ""),
                       ("puy", "Puy: Sbb vs smooth", ""), ("wada", "Wada merge", "")])
    def wada_at(wd):
        if wd.get("error"):
            return "fewer than 3 faces"
        return (f"r = {wd['r_wada']}" if wd["wada"] else "no") + f" (far at r={wd['r_max']}: {wd['far_rmax']:.3f})"

    by = {(x["condition"], x["window"]): x for x in rows}
    out.tables["finer"] = md_table([{
        "c": f["condition"], "w": f["window"], "g": f"{f['res']}²", "cert": cert(f), "st": f["status"],
        "p0": puy(by[(f["condition"], f["window"])]["map"]) if (f["condition"], f["window"]) in by else "—",
        "p1": f"{puy({'puy': f['puy_same_scale']})} ({f['puy_same_scale']['eps_nodes']:g} nodes)",
        "p2": f"{puy({'puy': f['puy_same_nodes']})} ({f['puy_same_nodes']['eps_nodes']:g} nodes)",
        "w1": wada_at(f["wada_same_scale"]), "w2": wada_at(f["wada_same_nodes"]),
    } for f in r.get("finer", [])], [("c", "condition", ""), ("w", "window", ""), ("g", "finer map", ""),
                                     ("cert", "its certificate (95 %)", ""), ("st", "map is", ""),
                                     ("p0", "Puy on the main map", ""), ("p1", "Puy, same ball in window units", ""),
                                     ("p2", "Puy, same ball in nodes", ""),
                                     ("w1", "Wada merge, same distance in window units", ""),
                                     ("w2", "Wada merge, 5 nodes", "")])
    out.tables["faces"] = md_table([{
        "c": x["condition"], "w": x["window"], "st": x["map"]["status"],
        **{f"f{i}": pm(x["map"]["faces"]["faces"][str(i)]["fraction"], x["map"]["faces"]["faces"][str(i)]["stderr"],
                       ".3f") for i in range(1, 7)},
        "none": fmt(x["map"]["faces"]["no_face"], ".3f"),
    } for x in rows], [("c", "condition", ""), ("w", "window", ""), ("st", "map is", ""),
                       *((f"f{i}", f"face {i}", "") for i in range(1, 7)), ("none", "no face", "")])

    out.tables["face_changes"] = md_table([{
        "c": x["condition"], "w": x["window"], "f": x["face"], "d": pm(x["diff"], x["diff_err"], ".3f"),
        "z": fmt(x["z"], ".1f"), "v": "changed" if x["changed"] else "not resolved",
        "cv": "yes" if x["both_converged"] else "no (statistics only)",
    } for x in r["summary"]["face_changes"]], [("c", "condition", ""), ("w", "window", ""),
                                               ("f", "face of the largest change", ""),
                                               ("d", "its fraction minus the preset's", ""), ("z", "z", ""),
                                               ("v", "beyond 3 errors", ""), ("cv", "both maps converged", "")])

    def ec(p):
        if p["eps_c_status"] == "fitted":
            return f"{p['eps_c']:.2g} (±{p['log10_eps_c_stderr']:.2f} dex)"
        return {"below": "below the counted scales", "above": "above the counted scales"}.get(p["eps_c_status"],
                                                                                                "undetermined")

    def late(p):
        hz = p["hazard"]
        if hz is None:
            return "—"
        w = hz["commit"]["windows"]
        if not w["h"]:
            return "— (fewer than 20 commits per window)"
        return " → ".join(pm(h, e, ".1f") for h, e in zip(w["h"], w["stderr"]))

    out.tables["pairs"] = md_table([{
        "c": x["condition"], "w": x["window"], "n": x["pairs"]["n_pairs"],
        "fl": f"{x['pairs']['floor_throw_flips']}/{x['pairs']['floor_throws']}",
        "emin": fmt(x["pairs"]["eps_smallest_counted"], ".0e"),
        "a": pm(x["pairs"]["alpha_fine"], x["pairs"]["alpha_fine_stderr"], ".2f"),
        "ae": fmt(x["pairs"]["alpha_fine_eps"], ".1e"), "ec": ec(x["pairs"]),
        "b": pm(x["pairs"]["beta"], x["pairs"]["beta_stderr"], ".2f"), "hz": late(x["pairs"]),
        "kl": pm(x["pairs"]["hazard"]["commit"]["kappa_late"], x["pairs"]["hazard"]["commit"]["kappa_late_stderr"],
                 ".1f") if x["pairs"]["hazard"] else "—",
        "z": fmt(x["pairs"]["hazard"]["commit"]["late_minus_first"]["z"], ".1f") if x["pairs"]["hazard"] else "—",
    } for x in rows], [("c", "condition", ""), ("w", "window", ""), ("n", "pairs per scale", ""),
                       ("fl", "throws changed at tol/10", ""), ("emin", "finest counted ε", ""),
                       ("a", "α (finest local slope)", ""), ("ae", "at ε", ""), ("ec", "ε_c", ""),
                       ("b", "β (above ε_c)", ""),
                       ("hz", "commit hazard, windows 50-75-90-97-100 % (1/s)", ""), ("kl", "κ_late (1/s)", ""),
                       ("z", "rise, last vs first (z)", "")])
    summary = c.results.get("summary") or {}
    if "hazards" in summary:
        out.tables["hazard_shapes"] = md_table([{
            "c": h["condition"], "w": h["window"], "conv": "yes" if h["converged"] else "no (not counted)",
            "shape": h["shape"]["shape"], "rise": fmt(h["rise_z"], ".1f"),
            "fall": fmt(h["shape"]["min_step_z"], ".1f"),
            "kl": pm(h["tail"]["value"], h["tail"]["stat"], ".1f"),
            "ts": (f"+{h['tail']['syst_hi']:.1f} / −{h['tail']['syst_lo']:.1f}" if h["tail"]["value"] is not None
                   else "—"),
            "dom": ("yes" if h["tail"]["syst_dominates"] else "no") if h["tail"]["value"] is not None else "—",
        } for h in summary["hazards"]], [("c", "condition", ""), ("w", "window", ""),
                                         ("conv", "numerics converged", ""), ("shape", "commit hazard's shape", ""),
                                         ("rise", "rise, last vs first (z)", ""),
                                         ("fall", "most negative step between windows (z)", ""),
                                         ("kl", "κ_late past 97 % (1/s)", ""),
                                         ("ts", "tail start 90 / 75 / 50 %: systematic (+ / −)", ""),
                                         ("dom", "systematic exceeds statistical", "")])
