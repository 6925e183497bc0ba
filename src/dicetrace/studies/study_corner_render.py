"""Study m (corner), drawn: the face map around the corner balance, the triple points, the tables and the verdict.

:func:`verdict` writes the section's conclusion on the writeup's section 4.3
from the results alone (it is stored in the results JSON, so the report
quotes it); :func:`render` draws the figures and tables, and writes the
throw through the first located triple point as a Rerun recording when the
``rerun`` package is installed (``recordings/m_triple_point.rrd`` of the
output folder, kept only under 2 MB).
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.analysis.corner import EDGE_AZIMUTHS
from dicetrace.analysis.plot import FACE_COLORS, plot_outcome_map
from dicetrace.ics import seed_slice
from dicetrace.simulate import Record, simulate
from dicetrace.sinks.rerun import write_rrd
from dicetrace.studies.context import Output
from dicetrace.studies.study_corner_models import HUNT_MODEL, config
from dicetrace.studies.text import fmt, md_table, pm

#: Largest recording kept (bytes).
MAX_RRD_BYTES = 2_000_000
#: A throw "passes near" the corner balance when its D_min is below this (rad-equivalent; the linear range).
NEAR_D = 0.05


def _deg(v):
    return None if v is None else math.degrees(v)


def faces_up(node: int) -> list[int]:
    """The faces that can come up from a balance on ``node`` (1-8): those opposite its own three (docs/model.md §3)."""
    k = node - 1
    at = [6 if k & 4 else 1, 5 if k & 2 else 2, 4 if k & 1 else 3]
    return sorted(7 - f for f in at)


def _vertices(R: dict) -> list[dict]:
    return [p for p in R["triple"]["points"] if p["status"] == "vertex"]


def verdict(R: dict) -> str:
    """The conclusion on the writeup's "a vertex in 6-D must connect 7 cells, so IC⁶ has none", from the results."""
    ph = R["rates"]["physical"]
    rings = R["face_maps"]["models"]["physical"]["rings"]
    three = [r for r in rings if r["spin_ratio"] == 0 and len(r["faces"]) == 3 and r["n_borders"] == 3]
    rest = [r for r in rings if r["spin_ratio"] == 0]
    off = max((r["max_offset"] or 0.0) for r in three) if three else None
    pts = R["triple"]["points"]
    verts = _vertices(R)
    clean = [p for p in verts if p.get("three_on_every_circle")]
    ctrl = [t["d_min"] for m in R["triple"]["maps"] for t in m["random"] + m["border"]]
    d_v = [p["throw"]["d_min"] for p in clean]
    if "range_syst_lo" in ph:
        z = ph["sigmas"]
        word = ("consistent" if abs(z) < 2 else "undetermined at that level" if abs(z) <= 3 else "a difference")
        rate = (f"{ph['rate']:.9f} /s (spread over directions {ph['stat']:.0e}, step cap and tolerance "
                f"{ph['numerics_syst']:.0e}, fit range +{ph['range_syst_hi']:.1e} / −{ph['range_syst_lo']:.1e} /s) lies "
                f"{abs(ph['relative']):.1e} of itself {'below' if ph['relative'] < 0 else 'above'} the slipping pivot's "
                f"root {ph['analytic']:.9f} /s; the fit range moves it by up to {ph['range_syst_relative']:.0e} of "
                f"itself, the step cap and tolerance by far less, and the offset is {fmt(z, '+.1f')} σ of the side it "
                f"lies on: {word}")
    else:  # results written before the error budget
        rate = (f"{ph['rate']:.9f} ± {ph['error']:.1e} /s matches the slipping pivot's {ph['analytic']:.9f} /s "
                f"({fmt(ph['sigmas'], '+.1f')} σ)")
    parts = [
        f"The corner balance has two unstable directions of equal rate: in `physical` the simulator's rate {rate}, "
        f"and a tilt keeps its direction to {ph['max_drift']:.1e} rad."]
    if three:
        parts.append(
            f"Released around it, the `physical` die shows three sectors (faces "
            f"{', '.join(str(f) for f in three[0]['faces'])}) on {len(three)} of {len(rest)} rings down to a tilt of "
            f"{min(r['tilt'] for r in three):.0e} rad, their borders on the edges' directions to "
            f"{_deg(off):.1e}°: the balance is a triple point of the release map, the crossing of a 2-D slice of "
            f"phase space with a stable manifold of codimension 2.")
    else:
        parts.append("The `physical` release map does not show three clean sectors on every ring.")
    parts.append(
        f"On the converged seed-slice maps, {len(pts)} of the {sum(m['n_candidates'] for m in R['triple']['maps'])} "
        f"clean three-face boxes were refined: {len(verts)} closed on a "
        f"point (a bisection box of {R['triple']['tol']:.0e} in the hunt's integrator), {len(clean)} of them with "
        f"three sectors on every circle down to {min(R['triple']['radii']):.0e} of the window.")
    rs = R["triple"].get("reproducibility") or {}
    if rs.get("n_points"):
        names = " and ".join(f"`{k}`" for k in R["triple"].get("independent", {}))
        n_with, n_without = rs.get("n_with_common_radius", rs["n_points"]), rs.get("n_without_common_radius", 0)
        where = (f"about {n_with} of them every integrator sees the three faces on circles down to "
                 f"{rs['radius_coarsest']:.0e} of the window, not below" if rs.get("radius_coarsest") is not None
                 else "about none of them do all integrators see the three faces on one circle")
        if n_without and rs.get("radius_coarsest") is not None:
            where += (f", and about {n_without} not even on the largest circle "
                      f"({rs.get('largest_radius', 1e-7):.0e} of the window)")
        spread = (f", {rs['spread_min']:.1e} … {rs['spread_max']:.1e} of the window from the hunt's point"
                  if rs.get("spread_max") is not None else "")
        parts.append(
            f"Located again by {names} (10× tighter), {rs['n_found_by_all']} of the {rs['n_points']} points are found "
            f"by every integrator with the same three faces{spread}; {where}. The location is reproducible across "
            f"integrators to about the integrators' spread, not to the hunt's box of {rs['box_max']:.0e} (slice "
            "units), which is one integrator's bisection.")
    if clean:
        med_c = float(np.median(ctrl)) if ctrl else math.nan
        same = sum(p["labels"] == faces_up(p["throw"]["node"]) for p in clean)
        parts.append(
            f"Their throws come within D = {min(d_v):.3g} … {max(d_v):.3g} of a corner balance (median of the "
            f"random and two-face-border throws: {med_c:.3g}), and at {same} of the {len(clean)} points the three "
            "faces that meet are the three that can come up from a balance on the node the throw comes nearest to.")
        below = max(d_v) < (min(ctrl) if ctrl else math.inf)
        if below and max(d_v) < NEAR_D:
            how = ("Every such throw passes nearer a corner balance than any control throw, within the linear range "
                   f"(D < {NEAR_D:g}): the corner balance is their mechanism.")
        elif below:
            how = ("Every such throw passes nearer a corner balance than any control throw, but none comes within "
                   f"the linear range (D < {NEAR_D:g}): they cross over a corner still turning, so the corner "
                   "balance is not shown to be their mechanism.")
        else:
            how = ("Not every such throw passes nearer a corner balance than the control throws, so the corner "
                   "balance is not shown to be their mechanism.")
        parts.append(
            "**Refuted:** the writeup's conclusion that a 2-D map has no triple points. Isolated points where three "
            "faces meet exist in the converged model's 2-D slices, as a codimension-2 set of the 6-D IC space must "
            "cut a generic plane. Its statement about vertices of the 6-D space itself (a vertex joining 7 cells) is "
            "untouched: nothing here measures it. " + how)
    elif three:
        parts.append(
            "**Refuted in principle** (the release map has its triple point at the balance, a codimension-2 set), "
            "but **undetermined** on the seed slice: no triple point of the converged maps was located here.")
    else:
        parts.append("**Undetermined.**")
    return " ".join(parts)


def render(c, out: Output) -> None:
    R = c.results
    _rates_table(R, out)
    _face_map_figure(R, c.plot["face_maps"], out)
    _triple_tables(R, out)
    _reproduced_table(R, out)
    _triple_figure(R, c.plot["maps"], out)
    _recording(R, out)


def _rates_table(R: dict, out: Output) -> None:
    ra = R["rates"]
    b = ra["balance"]
    ph = ra["physical"]
    rows = [
        {"model": ph["model"], "release": "at rest, 1e-10 rad",
         "analytic": b["physical"]["rate"], "rigid": b["physical"]["rate_rigid"],
         "sim": (f"{ph['rate']:.9f} +{ph['error_hi']:.1e} / −{ph['error_lo']:.1e}" if "error_hi" in ph
                 else pm(ph["rate"], ph["error"], ".9f")),
         "sig": ph["sigmas"], "drift": ph["max_drift"]},
        {"model": ra["seed_converged"]["model"], "release": f"turning, {ra['seed_converged']['tilt0']:.0e} rad",
         "analytic": b["seed"]["rate"], "rigid": b["seed"]["rate_rigid"],
         "sim": pm(ra["seed_converged"]["rate"], ra["seed_converged"]["error"], ".4f"),
         "sig": ra["seed_converged"]["sigmas"], "drift": ra["seed_converged"]["drift"]},
        {"model": ra["seed_discrete"]["model"], "release": "at rest, 1e-8 rad",
         "analytic": b["seed"]["rate"], "rigid": b["seed"]["rate_rigid"],
         "sim": pm((ra["seed_discrete"]["fit"] or {}).get("rate"), (ra["seed_discrete"]["fit"] or {}).get("stderr"),
                   ".2f"), "sig": None, "drift": ra["seed_discrete"]["fall_turn"]},
    ]
    out.tables["rates"] = md_table(rows, [("model", "model (integrator, tolerance)", ""), ("release", "release", ""),
                                          ("rigid", "rigid pivot λ₀ (1/s)", ".4f"),
                                          ("analytic", "analytic λ (1/s)", ".4f"), ("sim", "simulated λ (1/s)", ""),
                                          ("sig", "difference (σ)", "+.1f"),
                                          ("drift", "turn of the fall's direction (rad)", ".1e")])
    if "fit_ends" in ph:
        budget = [{"part": "directions", "how": f"{len(ph['runs'])} directions of the tilt, standard error of their mean",
                   "shift": f"± {ph['stat']:.1e}"}]
        for m in ph["numerics"]:
            budget.append({"part": "step cap and tolerance",
                           "how": f"output step (sub-step cap) {m['dt_s'] * 1e3:g} ms, tol {m['tol']:g}",
                           "shift": _signed(m["rate"] - ph["runs"][0]["rate"])})
        for key, what in (("fit_ends", "fit from 1e-6 rad to {:g} rad"), ("fit_starts", "fit from {:g} rad to 1e-3 rad")):
            sc = ph[key]
            for i, ((lo, hi), v) in enumerate(zip(sc["ranges"], sc["values"])):
                if i == sc["reference"]:
                    continue
                budget.append({"part": "fit range", "how": what.format(hi if key == "fit_ends" else lo),
                               "shift": _signed(v - sc["value"]) if v is not None else "–"})
        budget.append({"part": "total, the side of the analytic root",
                       "how": f"offset {ph['difference']:+.1e} /s ({ph['relative']:+.1e} of the rate)",
                       "shift": f"{ph['sigmas']:+.1f} σ"})
        out.tables["rate_budget"] = md_table(budget, [("part", "part of the budget", ""), ("how", "varied", ""),
                                                      ("shift", "shift of the rate (1/s)", "")])


def _signed(v: float) -> str:
    return f"{v:+.1e}"


def _face_map_figure(R: dict, plot: dict, out: Output) -> None:
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing


    fm = R["face_maps"]
    phis = np.asarray(fm["phis"])
    models = list(fm["models"])
    fig, axes = plt.subplots(1, len(models), figsize=(4.2 * len(models), 4.6), subplot_kw={"projection": "polar"})
    rows = []
    for ax, model in zip(np.atleast_1d(axes), models):
        m = fm["models"][model]
        width = 2 * math.pi / len(phis)
        for k, ring in enumerate(m["rings"]):
            labels = np.asarray(ring["labels"])
            ax.bar(phis, np.full(len(phis), 0.8), width=width, bottom=k + 0.6,
                   color=[FACE_COLORS.get(int(v), "grey") for v in labels], edgecolor="none")
            for bd in ring["borders"]:
                ax.plot([bd["phi"]] * 2, [k + 0.6, k + 1.4], color="cyan", lw=1.2)
            rows.append({"model": model, "tilt": ring["tilt"], "spin": ring["spin_ratio"],
                         "faces": " ".join(str(f) for f in ring["faces"]), "n": ring["n_borders"],
                         "on": ", ".join(ring.get("on", [])),
                         "phis": ", ".join(f"{_deg(bd['phi']):.4f}" for bd in ring["borders"]),
                         "off": _deg(ring["max_offset"]), "err": _deg(ring["max_error"])})
        for e in EDGE_AZIMUTHS:
            ax.plot([e, e], [0, len(m["rings"]) + 0.5], color="0.5", lw=0.6, ls=":")
        ax.set_yticks(np.arange(1, len(m["rings"]) + 1))
        ax.set_yticklabels([f"{r['tilt']:.0e}" + (" ↻" if r["spin_ratio"] else "") for r in m["rings"]], fontsize=6)
        ax.set_xticks(np.radians([0, 60, 120, 180, 240, 300]))
        ax.set_title(f"{model}\n{m['model']}", fontsize=8)
    fig.tight_layout()
    out.save_fig(fig, "m_corner_face_map", caption=(
        "Which face comes up when the die is released off its corner balance (pivot node 1, faces 4, 5, 6 can come "
        "up): each ring is a tilt (rad; ↻: released turning at λ·tilt toward φ + 90°), each colour a face "
        "(4 magenta, 5 yellow, 6 black; white: did not settle), φ the direction of the tilt; dotted: the "
        "pivot's edges; cyan: the sector borders, bisected to 1e-9 rad."))
    out.tables["face_map"] = md_table(rows, [("model", "model", ""), ("tilt", "tilt (rad)", ".0e"),
                                             ("spin", "spin ratio", "g"), ("faces", "faces", ""),
                                             ("n", "borders", "d"), ("phis", "borders at φ (°)", ""),
                                             ("on", "on the direction of", ""),
                                             ("off", "largest offset from the symmetry line (°)", ".2e"),
                                             ("err", "bisection error (°)", ".1e")])


def _triple_tables(R: dict, out: Output) -> None:
    T = R["triple"]
    out.tables["maps"] = md_table([{
        "window": m["window"], "res": m["res"], "cert": pm(m["certificate"]["fraction"], None, ".3f"),
        "floor": m["floor"]["fraction"], "conv": "yes" if m["converged"] else "no", "cand": m["n_candidates"],
        "hunted": m["n_hunted"], "evals": m["hunt_evals"],
        "rand": float(np.median([t["d_min"] for t in m["random"]])) if m["random"] else None,
        "bord": float(np.median([t["d_min"] for t in m["border"]])) if m["border"] else None} for m in T["maps"]],
        [("window", "window", ""), ("res", "grid", "d"), ("cert", "certificate (agreement, 10× tighter)", ""),
         ("floor", "chaos floor", ".3f"), ("conv", "converged", ""), ("cand", "clean 3-face boxes", "d"),
         ("hunted", "refined", "d"), ("evals", "throws", "d"), ("rand", "random throws: median D_min", ".3g"),
         ("bord", "border throws: median D_min", ".3g")])
    rows = []
    for p in T["points"]:
        th = p.get("throw") or {}
        rows.append({"window": p["window"], "box": f"{p['box'][0]},{p['box'][1]}", "status": p["status"],
                     "depth": p.get("depth"),
                     "labels": " ".join(str(v) for v in p.get("labels", [])), "x": p.get("x"), "y": p.get("y"),
                     "size": p.get("size"),
                     "circ": (" ".join(str(c["n_arcs"]) for c in p["circles"]) if "circles" in p else None),
                     "d": th.get("d_min"), "tilt": th.get("tilt"), "omega": th.get("omega"), "spin": th.get("spin"),
                     "t": th.get("t_min")})
    out.tables["points"] = md_table(rows, [
        ("window", "window", ""), ("box", "box", ""), ("status", "refinement", ""), ("depth", "depth", "d"),
        ("labels", "faces", ""),
        ("x", "x", ".12f"), ("y", "y", ".12f"), ("size", "bisection box, hunt's integrator", ".1e"),
        ("circ", "arcs on circles 1e-3 … 1e-7", ""), ("d", "D_min", ".3g"), ("tilt", "tilt at D_min (rad)", ".2e"),
        ("omega", "ω⊥ there (rad/s)", ".3g"), ("spin", "spin there (rad/s)", ".3g"), ("t", "at t (s)", ".3f")])


def _reproduced_table(R: dict, out: Output) -> None:
    rows = []
    for p in R["triple"]["points"]:
        rp = p.get("reproduced")
        if not rp:
            continue
        rel = rp["relocation"]
        for name in rp["faces"]:
            k = rel["names"].index(name)
            rows.append({"window": p["window"], "point": f"{p['x']:.9f}, {p['y']:.9f}",
                         "who": "hunt's" if name == "hunt" else name,
                         "faces": " / ".join(" ".join(str(f) for f in fs) for fs in rp["faces"][name]),
                         "dist": "–" if name == "hunt" else (f"{rel['distances'][k]:.1e}" if rel["found"][k]
                                                           else "not found"),
                         "box": p["size"] if name == "hunt" else (rp["relocated"][name].get("size")),
                         "scale": rp["reproducible_radius"] if name == "hunt" else None})
    out.tables["reproduced"] = md_table(rows, [
        ("window", "window", ""), ("point", "point (hunt's)", ""), ("who", "integrator", ""),
        ("faces", "faces around the circles of " + " / ".join(f"{r:.0e}" for r in R["triple"].get("repro_radii", []))
         + " of the window", ""),
        ("dist", "located again: distance from the hunt's point", ""), ("box", "its bisection box", ".1e"),
        ("scale", "every integrator sees the three faces down to (of the window)", ".0e")])


def _triple_figure(R: dict, maps: dict, out: Output) -> None:
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing


    T = R["triple"]
    fig, axes = plt.subplots(1, len(maps) + 1, figsize=(4.4 * (len(maps) + 1), 4.2))
    for ax, (w, s) in zip(axes, maps.items()):
        plot_outcome_map(s.labels, extent=s.window, ax=ax, legend=False,
                         title=f"{w} (converged, {s.labels.shape[0]}²)")
        for p in T["points"]:
            if p["window"] != w or "x" not in p:
                continue
            ok = p["status"] == "vertex"
            ax.plot(p["x"], p["y"], marker="*" if ok else "x", color="cyan" if ok else "0.6", ms=11 if ok else 6,
                    mec="k" if ok else None)
    ax = axes[-1]
    groups = [("random", [t["d_min"] for m in T["maps"] for t in m["random"]]),
              ("two-face border", [t["d_min"] for m in T["maps"] for t in m["border"]]),
              ("triple point", [p["throw"]["d_min"] for p in _vertices(R)])]
    for k, (name, v) in enumerate(groups):
        if v:
            ax.plot(np.full(len(v), k) + np.linspace(-0.15, 0.15, len(v)), v, "o", ms=4, label=name)
    ax.set_yscale("log")
    ax.set_xticks(range(len(groups)))
    ax.set_xticklabels([g[0] for g in groups], fontsize=8)
    out.save_plot(fig, ax, "m_triple_points", xlabel="", ylabel="D_min: closest approach to a corner balance",
                  title="How near each throw passes a corner balance", legend=False, caption=(
                      "Left: the converged maps, with the located triple points (stars) and the boxes that split "
                      "(grey crosses). Right: the closest approach D_min = min over the throw of "
                      "√(α² + (|ω⊥|/λ)² + (|U|/λd)²) (ω⊥: across the pivot–centre axis; 0 at the "
                      "corner balance, 0.62 at rest on an edge, 0.96 on a face) of the throws through the triple "
                      "points, against random throws and throws on two-face borders of the same maps."))


def _recording(R: dict, out: Output) -> None:
    try:
        import rerun  # noqa: F401  (optional here: without it the run writes no recording)
    except ImportError:
        out.tables["recording"] = "(no recording: the rerun package is not installed)"
        return
    verts = _vertices(R)
    if not verts:
        out.tables["recording"] = "(no recording: no triple point was located)"
        return

    p = verts[0]
    ic = seed_slice(np.array([p["x"]]), np.array([p["y"]]))[0]
    roll = simulate(ic, config=config(HUNT_MODEL), record=Record(states=True, energy=True))
    path = out.out / "recordings" / "m_triple_point.rrd"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_rrd(roll, path, name="corner triple point", ic_label=f"seed slice x={p['x']!r}, y={p['y']!r}")
    if path.stat().st_size > MAX_RRD_BYTES:
        path.unlink()
        out.tables["recording"] = "(recording over 2 MB, not kept)"
        return
    size = path.stat().st_size / 1e6
    out.tables["recording"] = (f"`recordings/m_triple_point.rrd` ({size:.2f} MB): the throw "
                               f"through the triple point at ({p['x']!r}, {p['y']!r}) of {p['window']}; open it with "
                               "`rerun recordings/m_triple_point.rrd`.")
