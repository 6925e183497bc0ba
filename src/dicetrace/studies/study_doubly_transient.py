"""Study n (doubly_transient): doubly transient chaos measured as such: f(ε) local slopes and ε_c, settling hazards, λ₁ on survivors.

Replaces the κ/λ test that section j withdraws.  For the ``physical`` preset at its γ and k,
at two other γ and two other k, and for the ``seed`` force law integrated to convergence,
random ICs of the zoom-out window of the seed slice (L in the program's convention) are
thrown with ``contact-tsit5`` at a uniform tolerance of 1e-10 (no loosening over the throw):

* each base IC and its neighbours at ``ε · |ic| · ξ`` (ξ a random unit 6-vector, one per
  scale, ε = 1e-10 … 1e-3; 10⁴ pairs per scale, 4000 for the weakly damped die, whose
  throws the floor test finds unconverged) give ``f(ε)``, its local slopes with bootstrap errors and the
  crossover ε_c (:func:`~dicetrace.analysis.doubly_transient.crossover_fit`);
* the numerical floor: the first base ICs and their neighbours rerun at tol 1e-11; a pair's
  verdict can change only where one of its throws does, so twice the fraction of throws whose
  outcome changes (95 % upper bound) bounds the floor of every scale; a scale counts only where
  that bound is below a third of ``f(ε)`` and at least ten pairs changed;
* the settling hazard against time (settle time and commit time, the last contact off the
  final face), against bounce number and against energy;
* each hazard's shape across its quantile windows (:func:`~dicetrace.analysis.doubly_transient.hazard_shape`:
  a steady rise, a dip before a rise, or not monotone) and the late hazard with the tail's start
  (90–99 % quantile) as its systematic (:func:`~dicetrace.analysis.doubly_transient.tail_scan`);
* λ₁ on throws that outlive the median settle time (pairs nudged by 1e-10), beside all throws;
* each model's analytic edge saddle (:func:`~dicetrace.analysis.border_rates.edge_saddle`) and,
  beside it, the edge-release rate; for ``seed`` the release diagnosed (:func:`release_diagnosis`:
  its fit starts inside a start transient, so it is no bound on the saddle);
* the two hypotheses with their z-scores: the final saddle is the edge balance, tested on the
  settle clock (the late settle hazard against α_fine·λ_edge, with the tail-start systematic, and
  α at fine scales against 1), against the chaotic-saddle relation α = κ/λ₁.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from dicetrace.analysis.border_rates import edge_saddle
from dicetrace.analysis.doubly_transient import (commit_steps, compare, covariate_hazard, crossover_fit, floor_test,
                                                 hazard_shape, hazard_summary, local_slopes, pair_divergence,
                                                 pair_outcomes, pair_verdicts, perturbed, tail_scan, throw_floor)
from dicetrace.analysis.edge import edge_release_rate
from dicetrace.analysis.lyapunov import finite_time_lyapunov
from dicetrace.analysis.robustness import one_sided_z
from dicetrace.analysis.settle import edge_balance_rate
from dicetrace.ics import seed_slice
from dicetrace.params import make_config
from dicetrace.studies.context import (Computed, Context, Output, jsonable, rerender_results,
                                       window_ranges)
from dicetrace.studies.text import fmt
from dicetrace.studies.study_doubly_transient_render import render as _render

NAME = "doubly_transient"
WINDOW = "zoom-out"
#: The uniform tolerance of every throw here, and the floor test's (10× tighter).
TOL, TOL_FLOOR = 1e-10, 1e-11
#: Nudge of the λ₁ pairs (relative to |ic|) and the distance (cm) where their fit stops.
LAMBDA_DELTA, LAMBDA_SATURATION = 1e-10, 1e-2
#: ε scales of the full run (relative 6-D IC perturbations): half decades where f is below saturation for the two
#: models of the answers table and the strongly damped die (its f is small down to 1e-7), whole decades elsewhere.
_PRESET_EPS = 10.0 ** np.r_[np.arange(-10, -6.9, 0.5), -6.0, -5.0]
_SEED_EPS = 10.0 ** np.r_[np.arange(-8, -3.9, 0.5), -3.0]
_DAMPED_EPS = 10.0 ** np.arange(-7, -2.9, 0.5)
_DECADES = 10.0 ** np.arange(-10.0, -2.5)
#: key -> (preset, make_config overrides, ε scales of the full run, base ICs (pairs per scale) of the full run).
#: γ 0.0025 runs 4000: its throws are not converged at these tolerances (the floor test says so), so more pairs
#: would measure nothing more.
CONDITIONS = {
    "physical": ("physical", {}, _PRESET_EPS, 10_000),
    "physical γ 0.0025": ("physical", {"gamma": 0.0025}, _DECADES, 4000),
    "physical γ 0.01": ("physical", {"gamma": 0.01}, _DAMPED_EPS, 10_000),
    "physical k 2e5": ("physical", {"k": 2e5}, _DECADES, 10_000),
    "physical k 5e6": ("physical", {"k": 5e6}, _DECADES, 10_000),
    "seed": ("seed", {"integrator": "contact-tsit5"}, _SEED_EPS, 10_000),
}
QUICK_CONDITIONS = ("physical", "physical γ 0.01", "seed")
#: ε scales of the quick run.
EPS_QUICK = 10.0 ** np.arange(-8, -1, 2)
#: A scale counts where the floor's 95 % upper bound (twice the throws' flip fraction) is below this fraction of f(ε)
#: and at least MIN_CHANGED pairs changed.
FLOOR_SHARE, MIN_CHANGED = 1.0 / 3.0, 10
#: ε_c is resolved only where at least this many counted scales lie below it (a smooth range measured, not the
#: crossover fit's reading of the finest scales).
EPS_C_MIN_BELOW = 2
#: The seed edge release, diagnosed: its steps (s), start tilts (rad) and the later starts (s) of the fit.
RELEASE_DTS, RELEASE_TILTS, RELEASE_STARTS = (1e-4, 5e-5, 2.5e-5), (1e-7, 1e-6, 1e-5), (0.1, 0.15, 0.2)


def _config(cond: str, tol: float):
    preset, over, _, _ = CONDITIONS[cond]
    return make_config(preset, tol=tol, tol_growth=0.0, **over)


def _edge_config(cfg):
    """The edge release's numerics: the model's, but ``seed`` (whose signed ground and degree-0 friction stop an
    error-controlled release at its first step) with ``contact-substep`` at dt 0.1 ms, as section k4 releases it."""
    if cfg.preset.name != "seed":
        return cfg
    return replace(cfg, numerics=replace(cfg.numerics, integrator="contact-substep", dt_s=1e-4))


def _numerics(cfg) -> dict:
    p, n = cfg.preset, cfg.numerics
    return {"preset": p.name, "gamma": p.gamma, "k": p.k, "integrator": n.integrator, "tol": n.tol,
            "tol_growth": n.tol_growth, "dt_s": n.dt_s}


def release_diagnosis(cfg) -> dict:
    """Why the ``seed`` die's edge release does not measure its edge saddle: released at every step of
    RELEASE_DTS and tilt of RELEASE_TILTS, the rate fitted as section k4 fits it (from ten times the start tilt to
    0.01 rad), the tilt 0.1 s after the release (the same for every start tilt where the release's first steps,
    not the tilt, set the motion), and the rate fitted from the later starts RELEASE_STARTS to 0.01 rad."""
    rows = []
    for dt in RELEASE_DTS:
        c = replace(cfg, numerics=replace(cfg.numerics, integrator="contact-substep", dt_s=dt))
        for tilt0 in RELEASE_TILTS:
            try:
                er = edge_release_rate(config=c, tilt0=tilt0)
            except ValueError as e:
                rows.append({"dt_s": dt, "tilt0": tilt0, "error": str(e)})
                continue
            t, tilt = er.t_s, er.tilt
            late = []
            for t0 in RELEASE_STARTS:
                try:
                    f = finite_time_lyapunov(t, tilt, saturation=0.01, t_min=max(t0, er.fit_range[0]))
                    late.append({"from_s": t0, "rate": f.exponent, "stderr": f.stderr})
                except ValueError:
                    late.append({"from_s": t0, "rate": math.nan, "stderr": math.nan})
            rows.append({"dt_s": dt, "tilt0": tilt0, "rate": er.rate, "stderr": er.stderr,
                         "fit_range": list(er.fit_range), "tilt_at_0_1_s": float(np.interp(0.1, t, tilt)),
                         "late": late})
    ok = [r for r in rows if "rate" in r]
    lates = [x["rate"] for r in ok for x in r["late"] if math.isfinite(x["rate"])]
    return {"rows": rows, "rate_min": min(r["rate"] for r in ok), "rate_max": max(r["rate"] for r in ok),
            "late_min": min(lates), "late_max": max(lates),
            "tilt_0_1_min": min(r["tilt_at_0_1_s"] for r in ok), "tilt_0_1_max": max(r["tilt_at_0_1_s"] for r in ok)}


def compare_with_syst(x: float, stat: float, syst_lo: float, syst_hi: float, y: float, y_err: float) -> dict:
    """:func:`~dicetrace.analysis.doubly_transient.compare` of ``x`` (statistical error ``stat``, one-sided
    systematic ``syst_lo``/``syst_hi``) with ``y`` ± ``y_err``: the z-score from the statistical errors alone
    (``z_stat``) and with the systematic of the side ``y`` lies on (``z``, which gives the verdict)."""
    c = compare(x, stat, y, y_err)
    ok = all(v is not None and math.isfinite(v) for v in (x, stat, y, y_err))
    z = one_sided_z(x, stat, syst_lo or 0.0, syst_hi or 0.0, y, y_err) if ok else math.nan
    verdict = ("undetermined" if not ok or not math.isfinite(z) else
               "consistent" if abs(z) < 2 else "inconsistent" if abs(z) > 3 else "undetermined")
    c.update(z_stat=c["z"], z=z if ok else math.nan, syst_lo=syst_lo, syst_hi=syst_hi, verdict=verdict,
             syst_dominates=bool(max(syst_lo or 0.0, syst_hi or 0.0) > stat) if ok else None)
    return c


def _traced(ctx: Context, cfg, ics, t_settle, rng, n_surv: int, n_rand: int) -> dict:
    """λ₁ on throws that outlive the median settle time and on random throws; the energy hazard (random throws)."""
    settled = np.flatnonzero(np.isfinite(t_settle))
    med = float(np.median(t_settle[settled]))
    surv = settled[t_settle[settled] > med]
    picks = {"survivors": rng.choice(surv, min(n_surv, len(surv)), replace=False),
             "all": rng.choice(settled, min(n_rand, len(settled)), replace=False)}
    out: dict = {"median_settle_s": med}
    e_series, e_events = ([], []), []
    for key, idx in picks.items():
        lam = []
        for i in idx:
            t, d, energy, tc, roll = pair_divergence(ics[i], cfg, delta=LAMBDA_DELTA, rng=int(rng.integers(2**31)))
            ctx.n_throws += 2
            try:
                lam.append(finite_time_lyapunov(t, d, saturation=LAMBDA_SATURATION, t_min=tc).exponent)
            except ValueError:
                pass
            if key == "all" and roll.outcome >= 1:
                c, _ = commit_steps(roll.contact_sets, roll.contact_steps, [0, len(roll.contact_sets)],
                                    [roll.outcome], [roll.steps])
                e_series[0].append(roll.trace.t_s)
                e_series[1].append(energy if len(energy) == len(roll.trace.t_s) else roll.trace.t_s * np.nan)
                e_events.append(c[0] * roll.dt_s)
        lam = np.asarray(lam)
        out[key] = {"n": int(len(lam)), "mean": float(lam.mean()) if len(lam) else math.nan,
                    "stderr": float(lam.std(ddof=1) / math.sqrt(len(lam))) if len(lam) > 1 else math.nan,
                    "median": float(np.median(lam)) if len(lam) else math.nan,
                    "q25": float(np.quantile(lam, 0.25)) if len(lam) else math.nan,
                    "q75": float(np.quantile(lam, 0.75)) if len(lam) else math.nan, "values": lam.tolist()}
    edges = np.geomspace(0.7, 50.0, 15)
    out["energy_hazard"] = covariate_hazard(e_series[0], e_series[1], e_events, edges).as_dict()
    return out


def _measure(ctx: Context, cond: str, index: int) -> dict:
    t_start = time.perf_counter()
    cfg, tight = _config(cond, TOL), _config(cond, TOL_FLOOR)
    eps = EPS_QUICK if ctx.quick else CONDITIONS[cond][2]
    n, n_floor = ctx.pick(CONDITIONS[cond][3], 300), ctx.pick(CONDITIONS[cond][3] // 10, 100)
    rng = np.random.default_rng([ctx.options.seed, index])
    (x0, x1), (y0, y1) = window_ranges(WINDOW)
    ics = cfg.to_preset_convention(np.asarray(seed_slice(rng.uniform(x0, x1, n), rng.uniform(y0, y1, n))), "program")
    moved = [perturbed(ics, e, rng) for e in eps]
    b, out = pair_outcomes(ics, moved, cfg)
    ctx.n_throws += out.size
    changed, valid = pair_verdicts(out)
    _, out_t = pair_outcomes(ics[:n_floor], [m[:n_floor] for m in moved], tight)
    ctx.n_throws += out_t.size
    changed_t, valid_t = pair_verdicts(out_t)
    floor = floor_test(changed[:n_floor], changed_t, valid=valid[:n_floor] & valid_t)
    tf = throw_floor(out[:, :n_floor], out_t)
    single_flips = int(tf["flips"])
    ls = local_slopes(changed, eps, valid=valid, n_boot=ctx.pick(400, 50), rng=rng)
    p = np.bincount(out[0][out[0] >= 1], minlength=7)[1:] / max((out[0] >= 1).sum(), 1)
    f_sat = float(1 - (p**2).sum())
    floor_bound = min(2 * float(tf["hi"]), 1.0)
    counted = (floor_bound <= FLOOR_SHARE * ls.f) & (ls.changed >= MIN_CHANGED)
    cx = crossover_fit(changed, eps, used=counted, valid=valid, f_sat=f_sat, n_boot=ctx.pick(200, 20), rng=rng)
    both = counted[:-1] & counted[1:] & np.isfinite(ls.slope_stderr)
    fine = int(np.flatnonzero(both)[0]) if both.any() else -1
    alpha_fine = (float(ls.slope[fine]), float(ls.slope_stderr[fine])) if fine >= 0 else (math.nan, math.nan)

    base = out[0] >= 1
    dt, t_cap = cfg.numerics.dt_s, cfg.numerics.t_max_s
    sl = slice(0, n)
    commit, landings = commit_steps(b.sets, b.set_steps, b.set_offsets[: n + 1], b.outcome[sl], b.steps[sl])
    t_settle = np.where(base, b.t_settle_s[sl], np.nan)
    hz = hazard_summary(t_settle[base], commit[base] * dt, landings[base], t_cap)
    n_s, n_r = ctx.pick(100 if cond in ("physical", "seed") else 50, 6), ctx.pick(200 if cond == "physical" else 60, 8)
    tr = _traced(ctx, cfg, ics, t_settle, rng, n_s, n_r)
    try:
        er = edge_release_rate(config=_edge_config(cfg), tilt0=1e-6)
        edge = {"rate": er.rate, "stderr": er.stderr, "fit_range": list(er.fit_range),
                "numerics": _numerics(_edge_config(cfg))}
    except ValueError as e:
        edge = {"rate": math.nan, "stderr": math.nan, "error": str(e)}
    ctx.n_throws += 1
    saddle = edge_saddle(config=cfg)
    lam_edge = saddle.rate
    diagnosis = None
    if cfg.preset.name == "seed" and not ctx.quick:
        diagnosis = release_diagnosis(cfg)
        ctx.n_throws += len(diagnosis["rows"])
    lam1, lam1_se = tr["survivors"]["mean"], tr["survivors"]["stderr"]
    k_mid, k_mid_se = hz["commit"]["kappa_mid"], hz["commit"]["kappa_mid_stderr"]
    ratio = k_mid / lam1 if lam1 else math.nan
    ratio_se = ratio * math.hypot(k_mid_se / k_mid, lam1_se / lam1) if lam1 and k_mid else math.nan
    shapes = {k: hazard_shape(hz[k]["windows"]["h"], hz[k]["windows"]["stderr"]) for k in ("commit", "settle")}
    tails = {}
    for key, life in (("settle", t_settle[base]), ("commit", commit[base] * dt)):
        tails[key] = tail_scan(life, censored=life >= t_cap)
    st = tails["settle"]
    below = int(np.sum(np.asarray(eps)[counted] < cx.eps_c)) if cx.status == "fitted" else 0
    tests = {
        # the settle clock: an edge saddle predicts κ = α·λ_edge with α the uncertainty exponent at the scales the
        # late throws reach (the finest counted); the commit time can stop on arrival at the final edge
        "edge_settle": compare_with_syst(st["value"], st["stat"], st["syst_lo"], st["syst_hi"],
                                         alpha_fine[0] * lam_edge, alpha_fine[1] * lam_edge),
        "edge_settle_alpha1": compare_with_syst(st["value"], st["stat"], st["syst_lo"], st["syst_hi"], lam_edge, 0.0),
        "edge_alpha_fine": compare(alpha_fine[0], alpha_fine[1], 1.0, 0.0),
        "saddle_beta": compare(cx.beta, cx.beta_stderr, ratio, ratio_se),
        "saddle_alpha_fine": compare(alpha_fine[0], alpha_fine[1], ratio, ratio_se),
    }
    row = {
        "condition": cond, **_numerics(cfg), "floor_tol": TOL_FLOOR, "window": WINDOW, "n_pairs": n,
        "n_floor_pairs": n_floor, "unsettled": int((~base).sum()), "f_sat": f_sat,
        "eps": eps.tolist(), "f": ls.f.tolist(), "f_stderr": ls.f_stderr.tolist(), "changed": ls.changed.tolist(),
        "pairs": ls.n.tolist(), "eps_mid": ls.eps_mid.tolist(), "slope": ls.slope.tolist(),
        "slope_stderr": ls.slope_stderr.tolist(), "floor_fraction": floor["fraction"].tolist(),
        "floor_hi": floor["hi"].tolist(), "floor_flips": floor["flips"].tolist(), "counted": counted.tolist(),
        "used_in_fit": cx.used.tolist(), "floor_throw_flips": single_flips, "floor_throws": int(tf["n"]),
        "floor_throw_fraction": float(tf["fraction"]), "floor_throw_hi": float(tf["hi"]), "floor_bound": floor_bound,
        "eps_smallest_counted": float(eps[counted][0]) if counted.any() else math.nan,
        "alpha_fine": alpha_fine[0], "alpha_fine_stderr": alpha_fine[1],
        "alpha_fine_eps": float(ls.eps_mid[fine]) if fine >= 0 else math.nan,
        "eps_c": cx.eps_c, "log10_eps_c_stderr": cx.log10_eps_c_stderr, "eps_c_status": cx.status,
        "eps_c_counted_below": below, "eps_c_resolved": bool(cx.status == "fitted" and below >= EPS_C_MIN_BELOW),
        "beta": cx.beta, "beta_stderr": cx.beta_stderr, "crossover_boot": cx.n_boot,
        "hazard": hz, "hazard_shape": shapes, "tail": tails, "lambda": tr, "edge_rate": edge,
        "edge_rate_analytic": edge_balance_rate(), "edge_saddle": lam_edge, "edge_saddle_pivot": saddle.friction,
        "release_diagnosis": diagnosis,
        "kappa_over_lambda1": ratio, "kappa_over_lambda1_stderr": ratio_se, "tests": tests,
        "wall_s": time.perf_counter() - t_start,
    }
    ctx.log(f"{cond}: α_fine {alpha_fine[0]:.2f} ± {alpha_fine[1]:.2f} at ε {row['alpha_fine_eps']:.1e}, "
            f"ε_c {cx.eps_c:.2g} ({cx.status}), β {cx.beta:.2f}, κ_mid {k_mid:.2f}, κ_late "
            f"{hz['commit']['kappa_late']:.2f} /s, settle κ_late {fmt(st['value'], '.2f')} ± {fmt(st['stat'], '.2f')} "
            f"(tail syst +{fmt(st['syst_hi'], '.2f')}/−{fmt(st['syst_lo'], '.2f')}), λ₁ {lam1:.2f} ± {lam1_se:.2f} /s, "
            f"edge release "
            f"{edge['rate']:.2f} /s, edge saddle {lam_edge:.2f} /s; commit hazard {shapes['commit']['shape']}")
    return row


def compute(ctx: Context) -> Computed:
    conds = QUICK_CONDITIONS if ctx.quick else tuple(CONDITIONS)
    rows = [_measure(ctx, c, i) for i, c in enumerate(conds)]
    by = {r["condition"]: r for r in rows}
    return Computed({"rows": rows, "by": by, "window": WINDOW, "tol": TOL, "floor_tol": TOL_FLOOR,
                     "lambda_delta": LAMBDA_DELTA, "lambda_saturation_cm": LAMBDA_SATURATION,
                     "floor_share": FLOOR_SHARE, "min_changed": MIN_CHANGED})


def render(c: Computed, out: Output) -> None:
    _render(c, out)


def rerender(out) -> dict:
    """Draw the figures and tables again from ``OUT/results/doubly_transient.json`` alone (the render reads nothing
    else) and write them back into it: no simulation, no measured number changed (each hazard's shape, a function
    of its stored windows, is derived again)."""
    def derive(r):
        for row in r["rows"]:  # a pure function of the stored windows: derived again with the code
            if "hazard_shape" in row:
                row["hazard_shape"] = jsonable({k: hazard_shape(row["hazard"][k]["windows"]["h"],
                                                                row["hazard"][k]["windows"]["stderr"])
                                                for k in ("commit", "settle")})
        r["by"] = {row["condition"]: row for row in r["rows"]}

    return rerender_results(out, NAME, render, derive)
