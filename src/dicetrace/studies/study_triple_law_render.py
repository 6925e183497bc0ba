"""Study s's figure and tables (:mod:`dicetrace.studies.study_triple_law`): the closure counts, the spirals against
the spinning balance's prediction, D_min against distance, and the share of throws near a corner balance."""

from __future__ import annotations

import math

import numpy as np

from dicetrace.studies.context import Computed, Output
from dicetrace.studies.text import fmt, md_table, pm

LN10 = math.log(10.0)


def _figure(r: dict, out: Output) -> None:
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing

    rows = r["rows"]
    fig, axes = plt.subplots(1, 4, figsize=(20, 4.8))
    ax = axes[0]
    first = rows[0]
    from dicetrace.studies.context import window_ranges

    (x0, x1), (y0, y1) = window_ranges(first["window"])
    h = (x1 - x0) / (first["res"] - 1)
    style = {(True, "vertex"): ("*", "C3", "opposite pair, closed"), (True, "split"): ("x", "C3", "opposite pair, split"),
             (True, "unresolved"): ("+", "C3", "opposite pair, unresolved"),
             (False, "vertex"): ("*", "C0", "adjacent, closed"), (False, "split"): ("x", "C0", "adjacent, split"),
             (False, "unresolved"): ("+", "C0", "adjacent, unresolved")}
    for key, (m, col, lab) in style.items():
        bs = [b for b in first["boxes"] if (b["opposite"], b["status"]) == key]
        if bs:
            ax.plot([b.get("x", x0 + (b["box"][0] + 0.5) * h) for b in bs],
                    [b.get("y", y0 + (b["box"][1] + 0.5) * h) for b in bs], m, color=col,
                    ms=11 if m == "*" else 6, mec="k" if m == "*" else None, label=f"{lab} ({len(bs)})", ls="none")
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_title(f"{first['window']}: the hunted junctions", fontsize=9)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.legend(fontsize=6)
    # the winding per decade against the spin
    ax = axes[1]
    om = np.linspace(0.1, max([p["throw"]["spin"] for row in rows for p in row["points"]] + [20.0]) * 1.1, 200)
    from dicetrace.analysis.triple_law import spinning_corner
    from dicetrace.studies.study_corner_models import HUNT_MODEL, config

    cfg = config(HUNT_MODEL)
    sc = [spinning_corner(float(o), cfg=cfg) for o in om]
    ax.plot(om, [v.winding for v in sc], "k-", label="(Ω − ω_p)·ln10/λ, slipping pivot (derived)")
    ax.plot(om, [v.winding_issue for v in sc], "k--", lw=0.8, label="Ω·ln10/λ (the issue)")
    ax.plot(om, [v.winding_held for v in sc], "k:", lw=0.8, label="held pivot")
    for c in r["release_control"]:
        ax.plot(c["omega"], abs(c["fit"]["winding"]), "s", mfc="none", color="C3", ms=8)
    ax.plot([], [], "s", mfc="none", color="C3", label="releases at set Ω")
    for k, row in enumerate(rows):
        for p in row["points"]:
            sp = p["spiral"]
            if not sp:
                continue
            lo, hi = sp.get("syst_total_lo", 0.0), sp.get("syst_total_hi", 0.0)
            e = [[math.hypot(sp["stat"] or 0.0, lo)], [math.hypot(sp["stat"] or 0.0, hi)]]
            ax.errorbar(p["throw"]["spin"], abs(sp["winding"]), yerr=e,
                        xerr=p["prediction"]["omega_err"], fmt="o", color=f"C{k}", capsize=2)
        ax.plot([], [], "o", color=f"C{k}", label=f"{row['window']}: triple points")
    ax.set_xlabel("Ω, spin at the closest approach (rad/s)")
    ax.set_ylabel("borders' turn per decade of radius (rad)")
    ax.set_title("logarithmic spirals: winding against spin", fontsize=9)
    ax.legend(fontsize=6)
    # D_min against r
    ax = axes[2]
    for k, row in enumerate(rows):
        for p in row["points"]:
            rr = np.array([t["r"] for t in p["traced"]])
            dd = np.array([t["d_min"] for t in p["traced"]])
            ax.loglog(rr, dd, ".", color=f"C{k}", ms=3, alpha=0.6)
            st = p["stretch"]
            if st.get("J") is not None and math.isfinite(st["J"]):
                xx = np.geomspace(rr.min(), rr.max(), 50)
                ax.loglog(xx, np.sqrt(p["throw"]["d_min"] ** 2 + (st["J"] * xx ** st["beta"]) ** 2), "-",
                          color=f"C{k}", lw=0.7)
        ax.plot([], [], ".", color=f"C{k}", label=row["window"])
    ax.set_xlabel("r, distance from the point (fraction of the window)")
    ax.set_ylabel("D_min")
    ax.set_title("closest approach against distance; lines: √(D₀² + (J r^β)²)", fontsize=9)
    ax.legend(fontsize=7)
    # the share of random throws with D_min < D
    ax = axes[3]
    D = np.array(r["d_grid"])
    for k, row in enumerate(rows):
        sh = np.array(row["random"]["share"]["share"])
        se = np.array(row["random"]["share"]["stderr"])
        ok = sh > 0
        ax.errorbar(D[ok], sh[ok], yerr=se[ok], fmt="o", color=f"C{k}", capsize=2,
                    label=f"{row['window']}: random throws")
        pr = np.array(row["predicted"]["share"])
        good = pr > 0
        ax.plot(D[good], pr[good], "-", color=f"C{k}", lw=1, label=f"{row['window']}: located points, J r^β")
        p2 = np.array(row["predicted"]["share_d2"])
        good = p2 > 0
        ax.plot(D[good], p2[good], ":", color=f"C{k}", lw=1, label=f"{row['window']}: D² law (β = 1)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_ylim(1e-6, 1.5)
    ax.set_xlabel("D")
    ax.set_ylabel("share with D_min < D")
    ax.set_title("throws passing near a corner balance", fontsize=9)
    ax.legend(fontsize=6)
    fig.tight_layout()
    out.save_fig(fig, "s_triple_law", caption="The triple-point law. Left: the junctions hunted in the first window "
                 "(stars: closed on a point; crosses: split; plus: unresolved), red where their three faces hold an "
                 "opposite pair. Second: each closed point's winding per decade of radius (bars: statistical, fit "
                 "range and integrator errors) against the spin of its throw at the closest approach to the corner "
                 "balance, with the releases off the balance at set spins (squares) and the three readings of the "
                 "law. Third: D_min of throws on circles about each point against the circle's radius. Right: the "
                 "share of random throws of each window with D_min < D (Poisson bars) against the share the located "
                 "points predict from their fitted J, β (solid) and with β = 1 (dotted).")


def render(c: Computed, out: Output) -> None:
    r = c.results
    rows = r["rows"]
    _figure(r, out)
    cl = []
    for row in rows + [{"window": "both", "closure": r["summary"]["closure"]}]:
        for cls in ("opposite", "adjacent"):
            t = row["closure"][cls]
            cl.append({"window": row["window"], "class": "an opposite pair" if cls == "opposite" else
                       "three adjacent faces", "n": t["n"], "closed": t["closed"], "split": t["split"],
                       "unresolved": t["unresolved"],
                       "fraction": (f"{fmt(t['fraction'], '.2f')} ({fmt(t['lo95'], '.2f')}–{fmt(t['hi95'], '.2f')})"
                                    if t["closed"] else f"0 (≤ {fmt(t['hi95'], '.3f')})")})
    out.tables["closure"] = md_table(cl, [
        ("window", "window", ""), ("class", "faces of the junction", ""), ("n", "hunted", "d"),
        ("closed", "closed", "d"), ("split", "split", "d"), ("unresolved", "unresolved", "d"),
        ("fraction", "closing fraction (95 % limits)", "")])
    mp = []
    for row in rows:
        ct = row["certificate"]
        mp.append({"window": row["window"], "grid": row["res"], "map_s": row["map_wall_s"],
                   "cert": f"{fmt(ct['tightened']['fraction'], '.4f')} / {fmt(ct['floor']['fraction'], '.4f')} "
                           f"({ct['nodes']} nodes)",
                   "conv": "yes" if ct["converged"] else "no", "boxes": row["n_boxes"], "clusters": row["n_clusters"],
                   "opp": row["n_opposite_clusters"], "hunted": row["n_hunted"], "evals": row["hunt_evals"],
                   "closed": row["n_closed"], "examined": row["n_examined"],
                   "splits": f"{row['split_confirmed']}/{len(row['split_certificate'])}",
                   "viol": row["opposite_vertices"]})
    out.tables["maps"] = md_table(mp, [
        ("window", "window", ""), ("grid", "grid", "d"), ("map_s", "map (s)", ".0f"),
        ("cert", "agreement 10× tighter / chaos floor", ""), ("conv", "converged", ""),
        ("boxes", "clean 3-face boxes", "d"), ("clusters", "junctions", "d"), ("opp", "of them with an opposite pair", "d"),
        ("hunted", "hunted", "d"), ("evals", "throws of the hunt", "d"), ("closed", "closed", "d"),
        ("examined", "examined (parts 2, 3)", "d"), ("splits", "splits confirmed by contact-dop853", ""),
        ("viol", "points with an opposite pair", "d")])
    sp = []
    for row in rows:
        for p in row["points"]:
            s_, pr = p["spiral"], p["prediction"]
            z = (s_ or {}).get("z") or {}
            sp.append({"window": row["window"], "faces": " ".join(str(v) for v in p["faces"]),
                       "omega": pm(p["throw"]["spin"], pr["omega_err"], ".3f"),
                       "common": fmt(p["common_radius"], ".0e"),
                       "spread": fmt(p["spread_over_width"], ".1e"),
                       "range": f"{s_['range'][0]:.0e}–{s_['range'][1]:.0e}" if s_ else "–",
                       "w": (f"{abs(s_['winding']):.4f} ± {fmt(s_['stat'], '.4f')} (+{s_['syst_total_hi']:.4f} / "
                             f"−{s_['syst_total_lo']:.4f})" if s_ else "–"),
                       "pred": pm(pr["winding"], pr["winding_err"], ".4f"), "z": fmt(z.get("winding"), ".1f"),
                       "issue": f"{pr['winding_issue']:.4f} ({fmt(z.get('winding_issue'), '.1f')})",
                       "held": f"{pr['winding_held']:.4f} ({fmt(z.get('winding_held'), '.1f')})",
                       "lam": pr["lam"]})
    out.tables["spirals"] = md_table(sp, [
        ("window", "window", ""), ("faces", "faces", ""), ("omega", "Ω at D_min (rad/s)", ""),
        ("common", "every integrator sees the faces down to", ""), ("spread", "relocated within (of the window)", ""),
        ("range", "fit range (of the window)", ""),
        ("w", "winding per decade (rad): ± stat (+/− range and integrators)", ""), ("lam", "λ(Ω) (1/s)", ".3f"),
        ("pred", "(Ω − ω_p)·ln10/λ, slipping pivot", ""), ("z", "z", ""),
        ("issue", "Ω·ln10/λ (z)", ""), ("held", "held pivot (z)", "")])
    rc = []
    for c_ in r["release_control"]:
        rc.append({"omega": c_["omega"], "n": c_["n_three"], "w": c_["fit"]["winding"], "pred": c_["prediction"]["winding"],
                   "rel": c_["relative"], "issue": c_["prediction"]["winding_issue"], "held": c_["prediction"]["winding_held"],
                   "lam": c_["prediction"]["lam"], "wp": c_["prediction"]["omega_p"], "c": c_["prediction"]["slip_c"]})
    out.tables["release"] = md_table(rc, [
        ("omega", "Ω (rad/s)", "g"), ("c", "pivot friction c (1/s·node mass)", ".1f"), ("lam", "λ(Ω) (1/s)", ".4f"),
        ("wp", "ω_p (rad/s)", ".4f"), ("n", "rings with three sectors", "d"), ("w", "measured winding (rad/decade)", ".6f"),
        ("pred", "(Ω − ω_p)·ln10/λ", ".6f"), ("rel", "measured / predicted − 1", ".1e"),
        ("issue", "Ω·ln10/λ", ".4f"), ("held", "held pivot", ".4f")])
    dm = []
    for row in rows:
        for p in row["points"]:
            st = p["stretch"]
            dm.append({"window": row["window"], "faces": " ".join(str(v) for v in p["faces"]), "d0": st["d0"],
                       "J": st["J"], "beta": pm(st["beta"], st.get("beta_stderr"), ".3f"),
                       "pred": p["prediction"]["beta"], "z": st.get("beta_z"),
                       "range": f"{fmt(st.get('r_lo'), '.0e')}–{fmt(st.get('r_hi'), '.0e')}"})
    out.tables["stretch"] = md_table(dm, [
        ("window", "window", ""), ("faces", "faces", ""), ("d0", "D_min at the point", ".1e"),
        ("range", "radii fitted", ""), ("J", "J", ".3g"), ("beta", "β", ""), ("pred", "μ/(λ+μ)", ".3f"),
        ("z", "z", ".1f")])
    sh = []
    for row in rows:
        rd, pr = row["random"], row["predicted"]
        for k, d in enumerate(r["d_grid"]):
            sh.append({"window": row["window"], "D": d, "count": rd["share"]["count"][k],
                       "share": pm(rd["share"]["share"][k], rd["share"]["stderr"][k], ".2e"),
                       "pred": pr["share"][k], "d2": pr["share_d2"][k]})
    out.tables["share"] = md_table(sh, [
        ("window", "window", ""), ("D", "D", ".2g"), ("count", "random throws with D_min < D", "d"),
        ("share", "share", ""), ("pred", "located points (J r^β)", ".1e"), ("d2", "D² law (β = 1)", ".1e")])
