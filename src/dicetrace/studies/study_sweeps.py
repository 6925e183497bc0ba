"""Study q (sweeps): damping γ and ground stiffness k on three windows of the converged die, with certificates.

The ``physical`` preset at its γ and k, at two other γ and at two other k (one parameter moved at a time), in
the windows home [0, .1]², zoom-out [0, 1]² and red sea [1, 2] × [3.5, 4.5] of the seed slice (L in the program's
convention).  Each condition and window gets, with numerics chosen for each measurement:

* **an outcome map** (``contact-tsit5``, graded tolerance: :data:`MAP_TOL` loosening by :data:`MAP_GROWTH`/s, the
  schedule fit for outcomes only), its face fractions with moving-block bootstrap errors
  (:func:`~dicetrace.analysis.face_fractions.face_fractions`: the grid's nodes are correlated, so no χ² on their
  counts), the Puy fractal test (:func:`~dicetrace.analysis.fractality.basins_fractal_test`) and the Wada merge
  test (:func:`~dicetrace.analysis.wada.wada_merge_test`);
* **its certificate**: random nodes of the map thrown again with an independent integrator (``contact-substep``
  at dt 0.1 ms, the accuracy study's reference), the agreement with its Wilson interval; the map is
  *converged* where the agreement is at least :data:`CERTIFIED` and *statistics only* below; the reference
  itself checked on fewer nodes against a third integrator (``contact-adaptive`` at tol 1e-10);
* **f(ε) and its local slopes** (uniform tolerance 1e-10, the numerical floor at 1e-11, exactly as study n:
  :mod:`dicetrace.analysis.doubly_transient`'s ``local_slopes``, ``crossover_fit``, ``throw_floor``; study n's
  pair runner, verdicts and hazards), so ε_c, the finest counted local slope α and β;
* **the tail hazard** of committing to the final face and of settling, from the same base throws (uniform
  tolerance: settle times are a fit's input).

Then the Puy and Wada tests again on finer maps (:data:`FINER`, 161² against the main maps' 81²) of the preset in
home and of γ 0.01 in home and zoom-out, each with its own certificate: at the same ball radius and Wada distance in
window units (only the resolution changes) and at the same radius in nodes.

The figures and tables are drawn by :mod:`dicetrace.studies.study_sweeps_render`.
"""

from __future__ import annotations

import math
import time

import numpy as np

from dicetrace.analysis.agreement import agreement
from dicetrace.analysis.doubly_transient import (commit_steps, compare, crossover_fit, hazard_shape, hazard_summary,
                                                 local_slopes, tail_scan_windows,
                                                 pair_outcomes, pair_verdicts, perturbed, throw_floor)
from dicetrace.analysis.face_fractions import face_fractions
from dicetrace.analysis.fractality import basins_fractal_test
from dicetrace.analysis.simulator import run_on_slice, window_points
from dicetrace.analysis.wada import wada_merge_test
from dicetrace.ics import seed_slice
from dicetrace.params import make_config
from dicetrace.studies.context import (Computed, Context, Output, jsonable, rerender_results,
                                       window_ranges)
from dicetrace.studies.study_doubly_transient import FLOOR_SHARE, MIN_CHANGED, TOL, TOL_FLOOR
from dicetrace.studies.study_sweeps_render import render as _render
from dicetrace.studies.text import CONVERGED_MIN

NAME = "sweeps"
WINDOWS = ("home", "zoom-out", "red-sea")
QUICK_WINDOWS = ("zoom-out", "red-sea")
#: condition -> make_config overrides of the ``physical`` preset (one parameter moved at a time).
CONDITIONS = {
    "physical": {},
    "γ 0.0025": {"gamma": 0.0025},
    "γ 0.01": {"gamma": 0.01},
    "k 2e5": {"k": 2e5},
    "k 5e6": {"k": 5e6},
}
QUICK_CONDITIONS = ("physical", "γ 0.01", "k 5e6")
#: The maps' graded schedule: ``contact-tsit5`` from MAP_TOL, loosening by MAP_GROWTH per second.
MAP_INTEGRATOR, MAP_TOL, MAP_GROWTH = "contact-tsit5", 2e-10, 5.0
#: The independent reference of the certificate and the third integrator that checks it.
REFERENCE = {"integrator": "contact-substep", "dt_s": 1e-4}
REFERENCE_CHECK = {"integrator": "contact-adaptive", "tol": 1e-10, "tol_growth": 0.0}
#: A map is converged where its agreement with the reference is at least this: the report's rule.
CERTIFIED = CONVERGED_MIN
#: Relative IC perturbations of f(ε) (whole decades) and of the quick run.
EPS = 10.0 ** np.arange(-10.0, -2.5)
EPS_QUICK = 10.0 ** np.arange(-8.0, -1.0, 2.0)
#: Ball radius (grid nodes) of the Puy test, and its balls.
PUY_EPS, PUY_BALLS = 4, 1000
PUY_EPS_QUICK, PUY_BALLS_QUICK = 3, 100
#: The finer maps of the Puy and Wada tests: (condition, window) and their grid (the full and the quick run).
FINER = (("physical", "home"), ("γ 0.01", "home"), ("γ 0.01", "zoom-out"))
FINER_QUICK = (("physical", "zoom-out"),)
FINER_RES, FINER_RES_QUICK = 161, 37


def _config(cond: str, **numerics):
    return make_config("physical", **{**CONDITIONS[cond], **numerics})


def map_options(cond: str) -> dict:
    return {"preset": "physical", "integrator": MAP_INTEGRATOR, "tol": MAP_TOL, "tol_growth": MAP_GROWTH,
            **CONDITIONS[cond]}


def _numerics(cfg) -> dict:
    n = cfg.numerics
    return {"integrator": n.integrator, "tol": n.tol, "tol_growth": n.tol_growth, "dt_s": n.dt_s}


def _puy(g, eps: float, balls: int, rng) -> dict:
    try:
        pt = basins_fractal_test(g, eps=eps, n_balls=balls, rng=rng)
        return {"verdict": pt.verdict, "Sbb": pt.Sbb, "Sbb_stderr": pt.Sbb_stderr, "smooth": pt.smooth_Sbb,
                "band": list(pt.band), "eps_nodes": pt.eps, "n_balls": pt.n_balls, "error": None}
    except ValueError as e:
        return {"verdict": "undetermined", "eps_nodes": eps, "n_balls": balls, "error": str(e)}


def _wada(g, r_max: int) -> dict:
    try:
        wm = wada_merge_test(g, r_max=r_max, tol=0.01, exclude=(-1, 0))
        return {"wada": wm.wada, "r_wada": wm.r_wada, "r_max": int(r_max), "far_r1": float(wm.far_fraction[1]),
                "far_r5": float(wm.far_fraction[min(5, r_max)]), "far_rmax": float(wm.far_fraction[-1]),
                "n_labels": len(wm.labels), "error": None}
    except ValueError as e:
        return {"wada": None, "r_wada": None, "r_max": int(r_max), "error": str(e)}


def _certificate(ctx: Context, cond: str, window: str, res: int, g, rng) -> dict:
    """Random nodes of the map against the independent reference, and the reference against a third integrator."""
    pts, _, _ = window_points(window_ranges(window), res)
    n_cert, n_check = ctx.pick(400, 40), ctx.pick(100, 10)
    idx = rng.choice(len(pts), min(n_cert, len(pts)), replace=False)
    ref = run_on_slice(pts[idx], "seed", config=_config(cond, **REFERENCE)).outcome
    chk = run_on_slice(pts[idx[:n_check]], "seed", config=_config(cond, **REFERENCE_CHECK)).outcome
    ctx.n_throws += len(idx) + n_check
    cert = agreement(g.ravel()[idx], ref)
    return {"certificate": cert.as_dict(), "reference": _numerics(_config(cond, **REFERENCE)),
            "reference_check": agreement(ref[:n_check], chk).as_dict(),
            "reference_check_numerics": _numerics(_config(cond, **REFERENCE_CHECK)),
            "converged": bool(cert.fraction >= CERTIFIED),
            "status": "converged" if cert.fraction >= CERTIFIED else "statistics only"}


def _map(ctx: Context, cond: str, window: str, rng) -> dict:
    """The outcome map, its faces (block bootstrap), the Puy and Wada tests, and its certificate."""
    res = ctx.res(81, 25)
    opts = map_options(cond)
    g = ctx.sample(window, res, **opts).labels
    row: dict = {"res": res, "numerics": _numerics(make_config(**opts)),
                 "faces": face_fractions(g, n_boot=ctx.pick(500, 100), rng=rng)}
    row["puy"] = _puy(g, ctx.pick(PUY_EPS, PUY_EPS_QUICK), ctx.pick(PUY_BALLS, PUY_BALLS_QUICK), rng)
    row["wada"] = _wada(g, 5)
    row.update(_certificate(ctx, cond, window, res, g, rng))
    return row


def _finer(ctx: Context, cond: str, window: str, index: int) -> dict:
    """The Puy and Wada tests on a finer map of a window, with its own certificate: at the ball radius and Wada
    distance of the main maps in window units, rounded to whole nodes (so the scale tested is the same and only
    the resolution changes), and at the main maps' radius in nodes (a scale that many times finer)."""
    rng = np.random.default_rng([ctx.options.seed, 1000 + index])
    base, res = ctx.res(81, 25), ctx.pick(FINER_RES, FINER_RES_QUICK)
    opts = map_options(cond)
    g = ctx.sample(window, res, **opts).labels
    eps0, balls = ctx.pick(PUY_EPS, PUY_EPS_QUICK), ctx.pick(PUY_BALLS, PUY_BALLS_QUICK)
    scale = (res - 1) / (base - 1)
    row = {"condition": cond, "window": window, "res": res, "base_res": base, "scale": scale,
           "numerics": _numerics(make_config(**opts)),
           "puy_same_scale": _puy(g, int(round(eps0 * scale)), balls, rng), "puy_same_nodes": _puy(g, eps0, balls, rng),
           "wada_same_scale": _wada(g, int(round(5 * scale))), "wada_same_nodes": _wada(g, 5)}
    row.update(_certificate(ctx, cond, window, res, g, rng))
    ctx.log(f"finer {cond} {window} {res}²: certificate {row['certificate']['fraction']:.3f}, Puy "
            f"{row['puy_same_scale']['verdict']} (Sbb {row['puy_same_scale'].get('Sbb', math.nan):.3f}) at the same "
            f"scale, {row['puy_same_nodes']['verdict']} at {eps0} nodes; Wada r {row['wada_same_scale']['r_wada']}")
    return row


def _pairs(ctx: Context, cond: str, window: str, rng) -> dict:
    """f(ε), its local slopes, ε_c and the tail hazards at a uniform tight tolerance (study n's measures)."""
    cfg, tight = _config(cond, tol=TOL, tol_growth=0.0), _config(cond, tol=TOL_FLOOR, tol_growth=0.0)
    eps = EPS_QUICK if ctx.quick else EPS
    n, n_floor = ctx.pick(1000, 60), ctx.pick(150, 20)
    (x0, x1), (y0, y1) = window_ranges(window)
    ics = cfg.to_preset_convention(np.asarray(seed_slice(rng.uniform(x0, x1, n), rng.uniform(y0, y1, n))), "program")
    moved = [perturbed(ics, e, rng) for e in eps]
    b, out = pair_outcomes(ics, moved, cfg)
    _, out_t = pair_outcomes(ics[:n_floor], [m[:n_floor] for m in moved], tight)
    ctx.n_throws += out.size + out_t.size
    changed, valid = pair_verdicts(out)
    tf = throw_floor(out[:, :n_floor], out_t)
    ls = local_slopes(changed, eps, valid=valid, n_boot=ctx.pick(400, 50), rng=rng)
    p = np.bincount(out[0][out[0] >= 1], minlength=7)[1:] / max((out[0] >= 1).sum(), 1)
    floor_bound = min(2 * float(tf["hi"]), 1.0)
    counted = (floor_bound <= FLOOR_SHARE * ls.f) & (ls.changed >= MIN_CHANGED)
    cx = crossover_fit(changed, eps, used=counted, valid=valid, f_sat=float(1 - (p**2).sum()),
                       n_boot=ctx.pick(200, 20), rng=rng)
    both = counted[:-1] & counted[1:] & np.isfinite(ls.slope_stderr)
    fine = int(np.flatnonzero(both)[0]) if both.any() else -1
    base = out[0] >= 1
    commit, landings = commit_steps(b.sets, b.set_steps, b.set_offsets[: n + 1], b.outcome[:n], b.steps[:n])
    hz = hazard_summary(b.t_settle_s[:n][base], commit[base] * cfg.numerics.dt_s, landings[base], cfg.numerics.t_max_s) \
        if base.sum() >= 20 else None
    return {
        "numerics": _numerics(cfg), "floor_tol": TOL_FLOOR, "n_pairs": n, "n_floor_pairs": n_floor,
        "unsettled": int((~base).sum()), "eps": eps.tolist(), "f": ls.f.tolist(), "f_stderr": ls.f_stderr.tolist(),
        "changed": ls.changed.tolist(), "eps_mid": ls.eps_mid.tolist(), "slope": ls.slope.tolist(),
        "slope_stderr": ls.slope_stderr.tolist(), "counted": counted.tolist(),
        "floor_throw_flips": int(tf["flips"]), "floor_throws": int(tf["n"]), "floor_bound": floor_bound,
        "n_counted": int(counted.sum()),
        "eps_smallest_counted": float(eps[counted][0]) if counted.any() else math.nan,
        "alpha_fine": float(ls.slope[fine]) if fine >= 0 else math.nan,
        "alpha_fine_stderr": float(ls.slope_stderr[fine]) if fine >= 0 else math.nan,
        "alpha_fine_eps": float(ls.eps_mid[fine]) if fine >= 0 else math.nan,
        "eps_c": cx.eps_c, "log10_eps_c_stderr": cx.log10_eps_c_stderr, "eps_c_status": cx.status,
        "beta": cx.beta, "beta_stderr": cx.beta_stderr, "hazard": hz,
    }


def _measure(ctx: Context, cond: str, window: str, index: int) -> dict:
    t0 = time.perf_counter()
    rng = np.random.default_rng([ctx.options.seed, index])
    cfg = _config(cond)
    row = {"condition": cond, "window": window, "preset": "physical", "gamma": cfg.preset.gamma, "k": cfg.preset.k,
           "map": _map(ctx, cond, window, rng), "pairs": _pairs(ctx, cond, window, rng)}
    row["wall_s"] = time.perf_counter() - t0
    m, pr = row["map"], row["pairs"]
    ctx.log(f"{cond} {window}: certificate {m['certificate']['fraction']:.3f} ({m['status']}), Puy "
            f"{m['puy']['verdict']}, Wada r {m['wada'].get('r_wada')}, α_fine {pr['alpha_fine']:.2f} ± "
            f"{pr['alpha_fine_stderr']:.2f}, ε_c {pr['eps_c']:.2g} ({pr['eps_c_status']}), {row['wall_s']:.0f} s")
    return row


def compute(ctx: Context) -> Computed:
    conds, wins = (QUICK_CONDITIONS, QUICK_WINDOWS) if ctx.quick else (tuple(CONDITIONS), WINDOWS)
    rows = [_measure(ctx, c, w, i * len(wins) + j) for i, c in enumerate(conds) for j, w in enumerate(wins)]
    finer = [_finer(ctx, c, w, i) for i, (c, w) in enumerate(FINER_QUICK if ctx.quick else FINER)]
    by: dict = {}
    for r in rows:
        by.setdefault(r["condition"], {})[r["window"]] = r
    return Computed({"rows": rows, "by": by, "finer": finer, "windows": list(wins),
                     "conditions": {c: CONDITIONS[c] for c in conds},
                     "map_numerics": {"integrator": MAP_INTEGRATOR, "tol": MAP_TOL, "tol_growth": MAP_GROWTH},
                     "reference": REFERENCE, "reference_check": REFERENCE_CHECK, "certified": CERTIFIED,
                     "tol": TOL, "floor_tol": TOL_FLOOR, "floor_share": FLOOR_SHARE, "min_changed": MIN_CHANGED,
                     "summary": _summary(rows)})


def face_changes(rows) -> list[dict]:
    """Per window and condition, how far its face fractions lie from the preset's (``physical``): the largest
    |z| over the faces of the difference over the two block-bootstrap errors in quadrature (no χ² on the
    counts: the nodes are correlated), its face, and ``changed`` where that |z| exceeds 3."""
    base = {r["window"]: r for r in rows if r["condition"] == "physical"}
    out = []
    for r in rows:
        b = base.get(r["window"])
        if b is None or r is b:
            continue
        zs = []
        for f in range(1, 7):
            x, y = r["map"]["faces"]["faces"][str(f)], b["map"]["faces"]["faces"][str(f)]
            zs.append(compare(x["fraction"], x["stderr"], y["fraction"], y["stderr"]))
        absz = [abs(z["z"]) if math.isfinite(z["z"]) else -1.0 for z in zs]
        k = int(np.argmax(absz))
        out.append({"condition": r["condition"], "window": r["window"], "face": k + 1, "z": zs[k]["z"],
                    "diff": zs[k]["diff"], "diff_err": zs[k]["diff_err"], "changed": bool(absz[k] > 3),
                    "both_converged": bool(r["map"]["converged"] and b["map"]["converged"])})
    return out


#: A condition's hazard counts only where its numerics converge: its map's certificate is at least CONVERGED_MIN and
#: at most this share of its floor throws change face between the tolerance and a tenth of it.
FLOOR_FLIPS_MAX = 0.01


def numerics_converged(r: dict) -> bool:
    """Whether a row's numerics converge: its map is converged and its throws at the uniform tolerance keep their
    face at a tenth of it (at most FLOOR_FLIPS_MAX of the floor throws change)."""
    p = r["pairs"]
    return bool(r["map"]["converged"]) and p["floor_throw_flips"] <= FLOOR_FLIPS_MAX * p["floor_throws"]


def hazard_rows(rows) -> list[dict]:
    """Per row with a commit hazard: its shape across the quantile windows, the rise (last window against the
    first), the late hazard with the tail-start systematic (:func:`tail_scan_windows`), and whether the row's
    numerics converge (:func:`numerics_converged`)."""
    out = []
    for r in rows:
        hz = r["pairs"]["hazard"]
        if not hz:
            continue
        w = hz["commit"]["windows"]
        out.append({"condition": r["condition"], "window": r["window"], "converged": numerics_converged(r),
                    "rise_z": hz["commit"]["late_minus_first"]["z"], "shape": hazard_shape(w["h"], w["stderr"]),
                    "tail": tail_scan_windows(w)})
    return out


def _summary(rows) -> dict:
    """Counts of the verdicts over every map, the face changes against the preset's, and the tail hazard's rise (its
    z-score, last quantile window against the first) and shape, over every row and over the rows whose numerics
    converge (:func:`numerics_converged`), which alone count."""
    fc = face_changes(rows)
    hr = hazard_rows(rows)
    rise = [h["rise_z"] for h in hr if h["rise_z"] is not None and math.isfinite(h["rise_z"])]
    conv = [h for h in hr if h["converged"]]
    crise = [h["rise_z"] for h in conv if h["rise_z"] is not None and math.isfinite(h["rise_z"])]
    shapes = {}
    for h in conv:
        shapes.setdefault(h["shape"]["shape"], []).append(f"{h['condition']} / {h['window']}")
    return {"n_maps": len(rows), "n_converged": sum(r["map"]["converged"] for r in rows),
            "converged": [f"{r['condition']} / {r['window']}" for r in rows if r["map"]["converged"]],
            "n_puy_fractal": sum(r["map"]["puy"]["verdict"] == "fractal" for r in rows),
            "n_wada": sum(bool(r["map"]["wada"].get("wada")) for r in rows),
            "sbb_random_faces": math.log(6.0),  # the ball entropy of faces drawn at random (a reference, not a fit)
            "face_changes": fc, "n_face_changes": len(fc), "n_face_changed": sum(c["changed"] for c in fc),
            "n_hazard_rise": len(rise), "hazard_rise_z_min": min(rise) if rise else None,
            "hazard_rise_z_max": max(rise) if rise else None, "n_hazard_rise_z2": sum(z > 2 for z in rise),
            "n_hazard_rise_z3": sum(z > 3 for z in rise),
            "hazards": jsonable(hr), "floor_flips_max": FLOOR_FLIPS_MAX, "n_numerics_converged": len(conv),
            "numerics_converged": [f"{h['condition']} / {h['window']}" for h in conv],
            "n_converged_rise_z2": sum(z > 2 for z in crise), "n_converged_rise_z3": sum(z > 3 for z in crise),
            "converged_rise_z_min": min(crise) if crise else None,
            "converged_rise_z_max": max(crise) if crise else None,
            "converged_shapes": shapes,
            "n_converged_monotone_rise": len(shapes.get("rises", [])),
            "n_converged_weak_rise": len(shapes.get("rises weakly", [])),
            "n_converged_not_monotone": len(shapes.get("not monotone", [])) + len(shapes.get("dips, then rises", [])),
            "converged_not_monotone": shapes.get("not monotone", []) + shapes.get("dips, then rises", [])}


def render(c: Computed, out: Output) -> None:
    _render(c, out)


def rerender(out) -> dict:
    """Draw the figures and tables again from ``OUT/results/sweeps.json`` alone and write them back into it (the
    summary, which derives from its rows alone, is derived again): no simulation, no measured number changed."""
    def derive(r):
        r["summary"] = _summary(r["rows"])

    return rerender_results(out, NAME, render, derive)
