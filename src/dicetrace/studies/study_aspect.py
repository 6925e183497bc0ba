"""Study aspect: the home window's border fraction f(ε) and α against the die's aspect ratio.

The chaos study maps the cube's *home* window (the writeup's 2-D seed slice,
x, y ∈ [0, 0.1], :data:`dicetrace.windows.WINDOWS`): the same starting velocity and
angular momentum, and the die that lands.  Here the die is a square prism of
half-extents (1, 1, c)·the cube's half side (faces 3 and 4 the square ones), for the
aspects c in ``ASPECTS`` (c = 1 is the cube, bit for bit: the tests check it), with
the ``physical`` preset as it is (``contact-tsit5``, its tolerance schedule).

The physical die's cells in this window are far smaller than any grid of it that
fits the budget: a pilot found outcomes changing under moves of 10⁻⁵ of the
window's width in a tenth of the points (the chaos study's 201² map of it is border
almost everywhere).  So its border is measured by the uncertainty method
(Grebogi, McDonald, Ott & Yorke 1983; :func:`dicetrace.analysis.uncertainty.uncertainty_exponent_perturbation`)
on ``N_POINTS`` points drawn uniformly in the window (afresh for each aspect, from one
seed), each moved by ε in a random direction, at the scales ``EPS_REL`` (fractions of
the window's width, half a decade apart):

- f(ε), the *border fraction* at scale ε: the share of points whose face changes,
  with its 95 % Wilson interval (the points are independent), and its value at
  ``EPS_REF_REL`` compared across the aspects (Pearson's χ² of homogeneity) and with
  the cube (z of the two shares);
- the uncertainty exponent α, f ~ ε^α, fitted (weighted by the binomial variance of
  log f, :func:`~dicetrace.analysis.boundaries.fit_power_law`) over nested ranges of
  the unsaturated scales (≥ ``MIN_CHANGES`` changed points and f ≤ ``SAT_FRACTION``
  of the saturation 1 − Σ p², :func:`~dicetrace.analysis.scaling.saturation_level`)
  from the smallest up (:func:`dicetrace.analysis.robustness.range_scan`): the
  shortest range's α is quoted with its regression error and the range systematic
  (how far the wider ranges move it); the α of the aspects are compared by their χ²
  about the weighted mean (errors: the regression's and the systematic's larger side
  in quadrature);
- the face shares of the window: of the unperturbed points (Wilson intervals,
  :func:`dicetrace.analysis.fairness.face_counts`), and of the outcome map of the
  window, ``MAP_RES``² nodes (moving-block bootstrap,
  :func:`dicetrace.analysis.face_fractions.face_fractions`), drawn in the figure;
- the integrator check: the first ``N_CHECK`` points again with ``contact-dop853`` at a
  uniform tolerance 1e-10 (``INTEG_CHECK``), the share whose face agrees: where it
  misses by as much as f at the smallest scales, those scales hold the integrator's
  noise.

The control: a prism of aspect ``CONTROL`` = 1 + 10⁻⁹, thrown from the cube's own
points in the same directions.  It runs the prisms' code path (a full inertia tensor,
not the cube's isotropic one) with the cube's body to 10⁻⁹, so its agreement with the
cube's faces and its f(ε) beside the cube's say what that path alone does.

Run it with ``dicetrace analyze aspect --out analysis/aspect`` (it writes
``aspect.csv``, ``results.json``, ``aspect.md``, ``aspect.png`` and the maps,
``maps.npz``; ``--quick`` for a small check, into ``./dicetrace-results/aspect`` by
default).  The full run throws (``len(ASPECTS)`` + 1)·(``N_POINTS``·(``len(EPS_REL)`` + 1) +
``MAP_RES``² + ``N_CHECK``) = 230 000 dice, about 10 minutes on one core (the prisms run at
a few hundred throws a second a core, the cube several times faster).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

from dicetrace.analysis.boundaries import boundary_fraction, fit_power_law
from dicetrace.analysis.face_fractions import face_fractions
from dicetrace.analysis.fairness import face_counts
from dicetrace.analysis.grouping import wilson_interval
from dicetrace.analysis.robustness import range_scan
from dicetrace.analysis.scaling import local_slopes, saturation_level
from dicetrace.compile_clock import CompileClock, time_text
from dicetrace.params import make_config
from dicetrace.studies.outputs import write_figure, write_text, written
from dicetrace.windows import get_window

#: Aspects c of the square prisms (1, 1, c)·half side; 1 is the cube.
ASPECTS = (0.8, 0.9, 1.0, 1.1, 1.25)
WINDOW = "home"
#: Points of the uncertainty method per aspect, and its scales (fractions of the window's width).
N_POINTS = 2000
EPS_REL = tuple(float(v) for v in np.logspace(-8, -2, 13))
#: The scale at which the border fractions of the aspects are compared.
EPS_REF_REL = 1e-5
#: A scale enters α's fits with at least this many changed points and f at most this share of saturation.
MIN_CHANGES = 10
SAT_FRACTION = 0.5
#: The outcome map's nodes per axis (its face shares and the figure).
MAP_RES = 101
#: The integrator check: the first ``N_CHECK`` points again with an independent scheme at a tighter tolerance.
N_CHECK = 200
INTEG_CHECK = dict(integrator="contact-dop853", tol=1e-10, tol_growth=0.0)
#: The control: a prism within 10⁻⁹ of the cube, thrown from the cube's own points in the same directions: the prisms'
#: code path (a full inertia tensor) with the cube's body to 10⁻⁹, so what that path alone does to the outcomes and f.
CONTROL = 1.0 + 1e-9
SEED = 20191001
QUICK = dict(n_points=100, eps_rel=(1e-6, 1e-5, 1e-4, 1e-3, 1e-2), map_res=21, aspects=(0.8, 1.0, 1.25), min_changes=2,
             n_check=10)
#: The χ² p-value at and above which a quantity counts as the same for every aspect.
PASS_P = 0.05

__all__ = ["ASPECTS", "WINDOW", "N_POINTS", "EPS_REL", "EPS_REF_REL", "MAP_RES", "QUICK", "config", "exponent",
           "study", "summarise", "render"]


def config(aspect: float, **numerics):
    """The ``physical`` preset with the square prism of aspect ``aspect``: half-extents (1, 1, aspect)·half side
    (``numerics``: another integrator or tolerance)."""
    h = make_config("physical").preset.half_side_cm
    return make_config("physical", half_extents_cm=(h, h, h * float(aspect)), **numerics)


def exponent(eps, f, n: int, f_sat: float, min_changes: int = MIN_CHANGES) -> dict:
    """α over nested ranges of the unsaturated scales, from the smallest up (the shortest quoted), as plain data;
    ``alpha`` None (with ``error``) where fewer than three scales qualify."""
    eps, f = np.asarray(eps, dtype=float), np.asarray(f, dtype=float)
    ok = (f * n >= min_changes) & (f > 0) & (f <= SAT_FRACTION * f_sat)
    q = np.sort(eps[ok])
    out = {"scales": [float(e) for e in q]}
    if len(q) < 3:
        return {**out, "alpha": None, "error": f"only {len(q)} unsaturated scale(s) with ≥ {min_changes} changes"}
    w = n * f / np.maximum(1.0 - f, 1e-300)

    def fit(lo, hi):
        sel = ok & (eps >= lo) & (eps <= hi)
        r = fit_power_law(eps[sel], f[sel], weights=w[sel])
        return r.slope, r.slope_stderr

    scan = range_scan(fit, [(float(q[0]), float(q[k])) for k in range(2, len(q))])
    d = scan.as_dict()
    total = math.hypot(scan.stat, scan.syst) if math.isfinite(scan.stat) else scan.syst
    return {**out, "alpha": scan.value, "alpha_stderr": scan.stat, "alpha_syst": scan.syst, "alpha_error": total,
            "range": d}


def _one(c: float, n_points: int, eps_rel, map_res: int, seed: int, min_changes: int,
         n_check: int) -> tuple[dict, np.ndarray, np.ndarray]:
    from dicetrace.analysis.simulator import classify_on_slice, sample_window
    from dicetrace.analysis.uncertainty import uncertainty_exponent_perturbation

    (x0, x1), (y0, y1) = get_window(WINDOW, 2)
    width = min(x1 - x0, y1 - y0)
    rng = np.random.default_rng(seed)
    pts = np.c_[rng.uniform(x0, x1, n_points), rng.uniform(y0, y1, n_points)]
    cfg = config(c)
    classify = classify_on_slice("seed", config=cfg)
    base = classify(pts)
    eps = width * np.asarray(eps_rel, dtype=float)
    ue = uncertainty_exponent_perturbation(classify, pts, eps, rng, labels=base)
    f = np.asarray(ue.f)
    k = np.rint(f * n_points).astype(int)
    lo, hi = wilson_interval(k, n_points)
    f_sat = saturation_level(base)
    sl = local_slopes(eps, f, n_points)
    grid = sample_window(WINDOW, map_res, config=cfg).labels
    m = min(int(n_check), n_points)
    check = classify_on_slice("seed", config=config(c, **INTEG_CHECK))(pts[:m])
    agree = int(np.sum(check == base[:m]))
    alo, ahi = wilson_interval(agree, m) if m else (math.nan, math.nan)
    row = {"n_points": int(n_points), "eps_rel": [float(e) for e in eps_rel], "eps": eps.tolist(), "f": f.tolist(),
           "changed": k.tolist(), "f_low": np.asarray(lo, float).tolist(), "f_high": np.asarray(hi, float).tolist(),
           "f_sat": f_sat, "local_slope": [None if not math.isfinite(v) else float(v) for v in sl.slope],
           "local_slope_stderr": [None if not math.isfinite(v) else float(v) for v in sl.stderr],
           "local_eps_rel": (sl.eps_mid / width).tolist(),
           "integrator_check": {"points": m, "agree": agree, "agreement": agree / m if m else math.nan,
                                "ci_low": float(alo), "ci_high": float(ahi)},
           "points": face_counts(base), "map": {"res": int(map_res), **face_fractions(grid),
                                                "border_fraction_at_grid": float(boundary_fraction(grid))}}
    row.update(exponent(eps, f, n_points, f_sat, min_changes))
    faces = row["points"]["faces"]
    n_face = sum(faces)
    sq = faces[2] + faces[3]
    slo, shi = wilson_interval(sq, n_face) if n_face else (math.nan, math.nan)
    row["square_faces"] = {"share": sq / n_face if n_face else math.nan, "ci_low": float(slo), "ci_high": float(shi),
                           "count": int(sq), "n": int(n_face)}
    return row, grid.astype(np.int8), base


def study(*, n_points: int = N_POINTS, eps_rel=EPS_REL, map_res: int = MAP_RES, aspects=ASPECTS,
          min_changes: int = MIN_CHANGES, n_check: int = N_CHECK, control: float | None = CONTROL,
          say=print) -> dict:
    """The uncertainty method and the outcome map of the home window for every aspect (the maps under ``maps``),
    and the control prism ``control`` on the cube's points (under ``control``, with its agreement with the cube)."""
    out = {"window": WINDOW, "ranges": [list(w) for w in get_window(WINDOW, 2)], "aspects": [float(a) for a in aspects],
           "n_points": int(n_points), "eps_rel": [float(e) for e in eps_rel], "map_res": int(map_res),
           "seed": SEED, "min_changes": int(min_changes), "n_check": int(n_check),
           "integrator_check": INTEG_CHECK, "by": {}, "maps": {}}
    runs = [(float(c), SEED + j) for j, c in enumerate(aspects)]
    if control is not None and 1.0 in [c for c, _ in runs]:
        runs.append((float(control), dict(runs)[1.0]))  # the cube's points
    bases = {}
    for c, seed in runs:
        t0 = time.perf_counter()
        with CompileClock() as clock:
            row, grid, bases[c] = _one(c, n_points, eps_rel, map_res, seed, min_changes, n_check)
        wall = time.perf_counter() - t0
        throws = n_points * (len(eps_rel) + 1) + map_res * map_res + min(n_check, n_points)
        row.update(wall_s=wall, compile_s=clock.seconds, throws=throws, throws_per_s=throws / wall, seed=seed)
        if c == control and c not in aspects:
            agree = int(np.sum(bases[c] == bases[1.0]))
            lo, hi = wilson_interval(agree, n_points)
            row["agrees_with_cube"] = {"points": int(n_points), "agree": agree, "agreement": agree / n_points,
                                       "ci_low": float(lo), "ci_high": float(hi),
                                       "map_agreement": float(np.mean(grid == out["maps"]["1"]))}
            out["control"] = {"aspect": c, "offset": c - 1.0, **row}
            out["maps"]["control"] = grid
        else:
            out["by"][f"{c:g}"] = row
            out["maps"][f"{c:g}"] = grid
        a = row["alpha"]
        say(f"c {c!r}: f = {', '.join(f'{v:.3f}' for v in row['f'])}; α {'—' if a is None else f'{a:.3f}'} "
            f"({time_text(wall, clock.seconds, '.0f')})")
    return out


def summarise(data: dict) -> dict:
    """Across the aspects: f at the reference scale (homogeneity, each against the cube), α about its weighted mean,
    the square faces' share."""
    from scipy import stats

    by = data["by"]
    keys = list(by)
    out: dict = {}
    ref = int(np.argmin(np.abs(np.log(np.array(data["eps_rel"]) / EPS_REF_REL))))
    out["eps_ref_rel"] = data["eps_rel"][ref]

    def shares(values, ns, name):
        table = np.array([values, np.asarray(ns) - np.asarray(values)])
        row = {"values": (np.asarray(values) / np.asarray(ns)).tolist()}
        if (table.sum(axis=1) > 0).all() and len(keys) > 1:
            res = stats.chi2_contingency(table, correction=False)
            row.update(chi2=float(res.statistic), dof=int(res.dof), p_value=float(res.pvalue))
            row["same_for_every_aspect"] = bool(res.pvalue >= PASS_P)
        else:
            row.update(chi2=math.nan, dof=0, p_value=math.nan, same_for_every_aspect=None)
        if "1" in by:
            i1 = keys.index("1")
            z = {}
            for i, k in enumerate(keys):
                p1, p2 = values[i1] / ns[i1], values[i] / ns[i]
                pool = (values[i1] + values[i]) / (ns[i1] + ns[i])
                se = math.sqrt(pool * (1 - pool) * (1 / ns[i1] + 1 / ns[i]))
                z[k] = None if k == "1" or se == 0 else float((p2 - p1) / se)
            row["z_vs_cube"] = z
        row["min"], row["max"] = float(min(row["values"])), float(max(row["values"]))
        out[name] = row

    shares([by[k]["changed"][ref] for k in keys], [by[k]["n_points"] for k in keys], "border_fraction")
    shares([by[k]["square_faces"]["count"] for k in keys], [by[k]["square_faces"]["n"] for k in keys], "square_faces")
    have = [k for k in keys if by[k]["alpha"] is not None and math.isfinite(by[k]["alpha_error"]) and by[k]["alpha_error"] > 0]
    a = {"values": {k: by[k]["alpha"] for k in keys}, "aspects_fitted": have}
    if have:
        v = np.array([by[k]["alpha"] for k in have])
        e = np.array([by[k]["alpha_error"] for k in have])
        w = 1 / e**2
        mean = float(np.sum(w * v) / np.sum(w))
        chi2 = float(np.sum(w * (v - mean) ** 2))
        dof = len(have) - 1
        a.update(weighted_mean=mean, chi2=chi2, dof=dof, p_value=float(stats.chi2.sf(chi2, dof)) if dof else math.nan,
                 min=float(v.min()), max=float(v.max()), syst_dominates=[bool(by[k]["range"]["syst_dominates"])
                                                                         for k in have])
        a["same_for_every_aspect"] = bool(a["p_value"] >= PASS_P) if dof else None
        if "1" in have:
            c = by["1"]
            a["z_vs_cube"] = {k: None if k == "1" else float((by[k]["alpha"] - c["alpha"])
                                                           / math.hypot(by[k]["alpha_error"], c["alpha_error"]))
                              for k in have}
    out["alpha"] = a
    # the integrator's noise beside f: the share of faces contact-dop853 changes, against f at the smallest scale fitted
    noise = {}
    for k in keys:
        ic = by[k]["integrator_check"]
        f_fit = None
        if by[k]["alpha"] is not None:
            f_fit = float(by[k]["f"][by[k]["eps"].index(by[k]["scales"][0])])
        noise[k] = {"disagreement": 1.0 - ic["agreement"], "disagreement_high": 1.0 - ic["ci_low"],
                    "f_smallest_fitted": f_fit}
    d = [v["disagreement"] for v in noise.values()]
    below = [k for k, v in noise.items() if v["f_smallest_fitted"] is not None
             and v["f_smallest_fitted"] < v["disagreement"]]
    out["integrator_noise"] = {"by": noise, "disagreement_min": float(min(d)), "disagreement_max": float(max(d)),
                               "aspects_fitted_below_noise": below}
    if "control" in data and "1" in by:
        c, cube = data["control"], by["1"]
        n1, n2 = cube["n_points"], c["n_points"]
        k1, k2 = cube["changed"][ref], c["changed"][ref]
        pool = (k1 + k2) / (n1 + n2)
        se = math.sqrt(pool * (1 - pool) * (1 / n1 + 1 / n2))
        out["control"] = {"aspect": c["aspect"], "f_ref": k2 / n2, "cube_f_ref": k1 / n1,
                          "z": (k2 / n2 - k1 / n1) / se if se > 0 else None, **c["agrees_with_cube"]}
    return out


def _pm_ci(v, lo, hi, spec=".3f") -> str:
    return f"{v:{spec}} ({lo:{spec}}–{hi:{spec}})"


def _md_tables(data: dict, summary: dict) -> dict[str, str]:
    by = data["by"]
    keys = list(by)
    fe = ["| ε / width | " + " | ".join(f"c = {k}" for k in keys) + " |", "|" + "---|" * (len(keys) + 1)]
    for i, e in enumerate(data["eps_rel"]):
        fe.append(f"| {e:.1e} | " + " | ".join(_pm_ci(by[k]["f"][i], by[k]["f_low"][i], by[k]["f_high"][i])
                                               for k in keys) + " |")
    fe.append("| saturation 1 − Σp² | " + " | ".join(f"{by[k]['f_sat']:.3f}" for k in keys) + " |")
    ctl = data.get("control")
    if ctl is not None:
        fe[0] = fe[0][:-1] + f"| c = 1 + {ctl['aspect'] - 1:.0e} (control) |"
        fe[1] += "---|"
        for i in range(len(data["eps_rel"])):
            fe[2 + i] = fe[2 + i][:-1] + f"| {_pm_ci(ctl['f'][i], ctl['f_low'][i], ctl['f_high'][i])} |"
        fe[-1] = fe[-1][:-1] + f"| {ctl['f_sat']:.3f} |"
    bf, sq = summary["border_fraction"], summary["square_faces"]
    al = ["| c | α (shortest range) | regression error | range systematic (−/+) | α over every range | scales "
          f"(ε / width) | f at {summary['eps_ref_rel']:.0e}: z against the cube | square faces (3, 4) | z against the "
          "cube | DOP853 1e-10 agrees | throws/s |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    width = data["ranges"][0][1] - data["ranges"][0][0]
    for k in keys:
        m = by[k]
        zb = bf.get("z_vs_cube", {}).get(k)
        zs = sq.get("z_vs_cube", {}).get(k)
        s = m["square_faces"]
        ic = m["integrator_check"]
        if m["alpha"] is None:
            acells = f"— | — | — | — | {m['error']}"
        else:
            r = m["range"]
            every = ", ".join("—" if v is None else f"{v:.3f}" for v in r["values"])
            acells = (f"{m['alpha']:.3f} | {m['alpha_stderr']:.3f} | −{r['syst_lo']:.3f} / +{r['syst_hi']:.3f} | "
                      f"{every} | {m['scales'][0] / width:.0e}–{m['scales'][-1] / width:.0e}")
        al.append(f"| {k} | {acells} | {'—' if zb is None else f'{zb:+.1f}'} | "
                  f"{_pm_ci(s['share'], s['ci_low'], s['ci_high'])} | {'—' if zs is None else f'{zs:+.1f}'} | "
                  f"{ic['agree']} of {ic['points']} ({ic['ci_low']:.3f}–{ic['ci_high']:.3f}) | {m['throws_per_s']:.0f} |")
    fs = ["| c | " + " | ".join(f"face {f}" for f in range(1, 7)) + " | edge / unsettled |", "|" + "---|" * 8]
    for k in keys:
        p = by[k]["points"]
        n = sum(p["faces"])
        fs.append(f"| {k} | " + " | ".join(_pm_ci(p["faces"][i] / n, p["ci_low"][i], p["ci_high"][i])
                                           for i in range(6)) + f" | {p['edge']} / {p['unsettled']} |")
    a = summary["alpha"]
    same = {True: "yes", False: "no", None: "—"}
    cmp_ = ["| quantity | χ² | dof | p-value | the same for every aspect? |", "|---|---|---|---|---|",
            f"| border fraction f at ε = {summary['eps_ref_rel']:.0e} of the width | {bf['chi2']:.1f} | {bf['dof']} | "
            f"{bf['p_value']:.2g} | {same[bf['same_for_every_aspect']]} |",
            f"| square faces' share | {sq['chi2']:.1f} | {sq['dof']} | {sq['p_value']:.2g} | "
            f"{same[sq['same_for_every_aspect']]} |"]
    if "chi2" in a:
        cmp_.append(f"| α (about its weighted mean {a['weighted_mean']:.3f}) | {a['chi2']:.1f} | {a['dof']} | "
                    f"{a['p_value']:.2g} | {same[a['same_for_every_aspect']]} |")
    return {"f_eps": "\n".join(fe), "alpha": "\n".join(al), "faces": "\n".join(fs), "across": "\n".join(cmp_)}


def render(data: dict, summary: dict, out: Path, command: str, wall_s: float) -> dict[str, Path]:
    """``aspect.csv``, ``results.json``, ``aspect.md``, ``aspect.png`` and ``maps.npz`` in ``out``; their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    out.mkdir(parents=True, exist_ok=True)
    by = data["by"]
    rows = [{"aspect": float(k), "eps_rel": e, "f": f, "changed": c, "f_low": lo, "f_high": hi, "points": m["n_points"]}
            for k, m in by.items() for e, f, c, lo, hi in zip(m["eps_rel"], m["f"], m["changed"], m["f_low"], m["f_high"])]
    with written(out / "aspect.csv", "table") as tmp:
        pd.DataFrame(rows).to_csv(tmp, index=False)
    with written(out / "maps.npz", "maps") as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **{f"c_{k}": v for k, v in data["maps"].items()})
    tables = _md_tables(data, summary)
    caption = (f"Left: the home window of the physical die for square prisms (1, 1, c) ({data['map_res']}² nodes, "
               "colours: the face up; the cells are far smaller than the grid). Right: the border fraction f(ε) of "
               f"{data['n_points']} random points moved by ε (95 % intervals), with each aspect's shortest-range power "
               "law")
    plain = {k: v for k, v in data.items() if k != "maps"}
    results = {"command": command, "wall_s": wall_s, **plain, "summary": summary, "tables": tables,
               "figures": {"aspect": {"path": f"{out.name}/aspect.png", "caption": caption}}}
    with written(out / "results.json", "results") as tmp:
        Path(tmp).write_text(json.dumps(results, indent=1))
    n = len(by)
    fig = plt.figure(figsize=(2.0 * n + 4.0, 2.9))
    cmap = ListedColormap(["#000000", "#888888", "#e41a1c", "#377eb8", "#4daf4a", "#984ea3", "#ff7f00", "#ffff33"])
    (x0, x1), (y0, y1) = data["ranges"]
    span = 0.6 / n
    for i, (k, grid) in enumerate((k, g) for k, g in data["maps"].items() if k in by):
        ax = fig.add_axes([0.01 + i * span, 0.12, span * 0.94, 0.72])
        ax.imshow(np.asarray(grid).T + 1, origin="lower", cmap=cmap, vmin=0, vmax=7, extent=(x0, x1, y0, y1),
                  interpolation="nearest")
        ax.set_title(f"c = {k}", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    ax = fig.add_axes([0.68, 0.17, 0.3, 0.72])
    width = x1 - x0
    for j, (k, m) in enumerate(by.items()):
        e = np.array(m["eps_rel"])
        f = np.array(m["f"])
        pos = f > 0
        ax.errorbar(e[pos], f[pos], yerr=[(f - np.array(m["f_low"]))[pos], (np.array(m["f_high"]) - f)[pos]],
                    fmt="o", ms=3, color=f"C{j}", capsize=1.5,
                    label=f"c = {k}" + ("" if m["alpha"] is None else f", α {m['alpha']:.2f}"))
        if m["alpha"] is not None:
            lo, hi = m["range"]["ranges"][0]
            sel = (np.array(m["eps"]) >= lo) & (np.array(m["eps"]) <= hi)
            fw = np.array(m["f"])[sel]
            w = m["n_points"] * fw / np.maximum(1 - fw, 1e-300)
            fit = fit_power_law(np.array(m["eps"])[sel], fw, weights=w)
            ax.plot(e[sel], np.exp(fit.intercept) * (e[sel] * width) ** fit.slope, "-", color=f"C{j}", lw=1)
    ctl = data.get("control")
    if ctl is not None:
        e, f = np.array(ctl["eps_rel"]), np.array(ctl["f"])
        ax.plot(e[f > 0], f[f > 0], "k+--", lw=0.8, ms=5, label=f"c = 1 + {ctl['aspect'] - 1:.0e} (control)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("ε / window width", fontsize=8)
    ax.set_ylabel("f(ε)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=6)
    write_figure(fig, out / "aspect.png", dpi=110)
    write_text(out / "aspect.md", _markdown(data, summary, tables, command, wall_s), "summary")
    return {"csv": out / "aspect.csv", "json": out / "results.json", "summary": out / "aspect.md",
            "figure": out / "aspect.png", "maps": out / "maps.npz"}


def _control_text(c: dict) -> str:
    z = "" if c["z"] is None else f", z = {c['z']:+.1f}"
    return (f"The control, c = 1 + {c['aspect'] - 1:.0e} (the prisms' code path with the cube's body to that "
            "precision), thrown from the "
            f"cube's own points and moved in the same directions: it ends on the cube's face at {c['agree']} of "
            f"{c['points']} points ({c['ci_low']:.3f}–{c['ci_high']:.3f}), and its f at the reference scale is "
            f"{c['f_ref']:.3f} against the cube's {c['cube_f_ref']:.3f}{z}.")


def _markdown(data: dict, summary: dict, tables: dict, command: str, wall_s: float) -> str:
    bf = summary["border_fraction"]
    lines = [
        "# The home window against the aspect ratio: border fraction f(ε) and α", "",
        f"Command: `{command}` ({wall_s:.0f} s wall on this machine). Model: the `physical` preset as it is "
        "(contact-tsit5, its tolerance schedule); the die a square prism of half-extents (1, 1, c) cm (c = 1: the "
        f"cube); window {data['window']} of the seed slice. f(ε): the share of {data['n_points']} random points of "
        "the window whose face changes when moved by ε in a random direction (95 % Wilson interval).", "",
        tables["f_eps"], "", tables["alpha"], "",
        "α: the slope of log f against log ε (weighted by the binomial variance of log f) over the shortest of the "
        f"nested ranges of unsaturated scales (≥ {data['min_changes']} changed points, f ≤ {SAT_FRACTION:g} of the "
        "saturation), from the smallest scale up; its range systematic is how far the wider ranges move it.", "",
        "Face shares of the window (the unperturbed points, 95 % Wilson intervals):", "", tables["faces"], "",
        "Across the aspects:", "", tables["across"], "",
        *([_control_text(summary["control"]), ""] if "control" in summary else []),
        f"The border fraction at ε = {summary['eps_ref_rel']:.0e} of the width runs from {bf['min']:.3f} to "
        f"{bf['max']:.3f} over the aspects. The outcome maps ({data['map_res']}² nodes) are border at almost every "
        "node (the share of nodes with a neighbour of another face: "
        + ", ".join(f"{m['map']['border_fraction_at_grid']:.3f} at c = {k}" for k, m in data["by"].items())
        + "): their spacing is far above the cells' scale.", "",
    ]
    return "\n".join(lines)


def rerender(out: Path) -> dict[str, Path]:
    """Summarise and render again from ``out``'s ``results.json`` and ``maps.npz`` (no simulation): the committed
    numbers of the maps and points, the summary, tables and figure recomputed from them."""
    out = Path(out)
    res = json.loads((out / "results.json").read_text())
    with np.load(out / "maps.npz") as z:
        maps = {k[2:]: z[k] for k in z.files}
    keep = ("window", "ranges", "aspects", "n_points", "eps_rel", "map_res", "seed", "min_changes", "n_check",
            "integrator_check", "by", "control")
    data = {k: res[k] for k in keep if k in res} | {"maps": maps}
    return render(data, summarise(data), out, res["command"], res["wall_s"])


def _answer(res: dict) -> str:
    """The report's sentence on the aspect: what the numbers of ``res`` (the study's results) say, and only that."""
    s = res["summary"]
    bf, a = s["border_fraction"], s["alpha"]
    keys = list(res["by"])
    same = {True: "the same for every aspect", False: "not the same for every aspect", None: "not compared"}
    text = (f"The border fraction at ε = {s['eps_ref_rel']:.0e} of the window's width runs from {bf['min']:.3f} to "
            f"{bf['max']:.3f} over the aspects and is {same[bf['same_for_every_aspect']]} within its binomial errors "
            f"(χ² {bf['chi2']:.1f} on {bf['dof']} dof, p = {bf['p_value']:.2g})")
    if "chi2" in a:
        text += (f"; α, from {a['min']:.2f} to {a['max']:.2f}, is {same[a['same_for_every_aspect']]} at its "
                 f"errors (χ² {a['chi2']:.1f} on {a['dof']} dof, p = {a['p_value']:.2g})")
    lo, hi = keys[0], keys[-1]
    text += (f". The square faces' share of the window goes from {res['by'][lo]['square_faces']['share']:.3f} "
             f"(c = {lo}) to {res['by'][hi]['square_faces']['share']:.3f} (c = {hi}).")
    nz = s.get("integrator_noise")
    if nz is not None:
        below = nz["aspects_fitted_below_noise"]
        text += (f" `contact-dop853` at tol {res['integrator_check']['tol']:.0e} changes the face of "
                 f"{nz['disagreement_min']:.3f}–{nz['disagreement_max']:.3f} of the first {res['n_check']} points of "
                 "each aspect; " + (f"at {len(below)} of the {len(keys)} aspects ({', '.join('c = ' + k for k in below)}) "
                                    "f at the smallest scale of α's fit is below that share, so α there is fitted on "
                                    "scales that hold the integrator's noise beside the die's."
                                    if below else "f at the smallest scale of every α fit is above that share."))
    if "control" in s:
        text += " " + _control_text(s["control"])
    return text


#: Sentences of the report written from the numbers (``{{s:aspect.NAME}}``).
SENTENCES = {"answer": _answer}
