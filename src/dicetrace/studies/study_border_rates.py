"""Study o (border_rates): border λ fitted near the border with a uniform tight tolerance, against each preset's edge saddle.

The settle-time divergence T ≈ T0 − ln(d)/λ at cell borders, measured with numerics chosen for it.

For each preset (``seed``, the 2019 force law; ``physical``) the die is
integrated with ``contact-tsit5`` at a **uniform** tolerance of 1e-13
(``tol_growth`` 0: no loosening over the throw, unlike ``physical``'s
default, which loosens tenfold every 0.23 s and suits outcome maps only).
In each of two windows of the seed slice (home, zoom-out) lines are sampled
and the neighbouring points of different outcomes kept; a random choice of
them is bisected (all in lock-step) until the bracket is shorter than
1e-11, and the settle time is sampled at d = 1e-11 … 1e-3 (four per decade)
on both sides of each border, along its line.

Numerics at the bisection scale: the bracket ends and every profile point
are integrated again at a tenth of the tolerance (1e-14, the smallest the
integrators take); the fraction of verdicts that change is reported, and the
fit starts at the smallest distance from which on no verdict changes and the
median |ΔT| is at most the settle time's resolution (one output step,
1 ms).

Fit range: the local slope dT/d(−ln d) of every side, by least squares over
a sliding decade (five distances), pooled (median over sides); the
near-border range runs from that smallest stable distance to the last
window whose pooled slope is within 2 % of the slope of the first four
windows.  λ is fitted on every side over that range and over the whole
range from the same smallest distance to 1e-3 (for comparison), and the
median over sides gets a bootstrap error over borders (both sides of a
border resampled together) and a systematic error (the larger shift of the
median when the profile is integrated at tol/10 or the range is cut a decade
shorter).

λ moves with the fit range even inside the near-border range, so the number
quoted is the limit as the range shrinks (:func:`_range_limit`): λ over
nested ranges from d_lo, one decade (five distances) up to the whole range,
through :func:`dicetrace.analysis.robustness.range_scan`; the shortest range's
median with its bootstrap error, and as a one-sided range systematic how far
the ranges inside the near-border range and their straight-line extrapolation
to zero width lie from it; beside it the shifts at tol/10 and with a trimmed
mean.  The rates are compared with the analytic edge saddle of each
preset (:func:`dicetrace.analysis.border_rates.edge_saddle`) and the corner
balance's (:func:`dicetrace.analysis.corner.corner_balance`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from dicetrace.analysis.border_rates import (
    Brackets,
    bisect_many,
    border_bootstrap,
    edge_saddle,
    fit_sides,
    flat_range,
    line_crossings,
    local_slopes,
    profiles,
    tolerance_stability,
)
from dicetrace.analysis.corner import corner_balance
from dicetrace.analysis.robustness import one_sided_z, range_scan, stat_syst, syst_note
from dicetrace.analysis.simulator import classify_on_slice, settle_on_slice
from dicetrace.params import make_config
from dicetrace.studies import LETTERS
from dicetrace.studies.context import Computed, Context, Output, window_ranges, write_json
from dicetrace.studies.text import fmt, md_table, pm

NAME = "border_rates"
#: The raw measurements (``results/<RAW_CSV>.csv``): every border, side and distance (in a folder of their own:
#: the report quotes none of these numbers, it quotes what the study computed from them).
RAW_CSV = "raw/border_rates_profiles"
#: The models: make_config options of each preset at the uniform tight tolerance.
TOL = 1e-13
CHECK_TOL = 1e-14
MODELS = {"seed": {"preset": "seed", "integrator": "contact-tsit5", "tol": TOL, "tol_growth": 0.0},
          "physical": {"preset": "physical", "integrator": "contact-tsit5", "tol": TOL, "tol_growth": 0.0}}
WINDOWS = ("home", "zoom-out")
#: Bracket length at which the bisection stops, slice units.
BISECT_WIDTH = 1e-11
#: Distances of the settle-time profile, slice units (four per decade).
DISTS = np.logspace(-11, -3, 33)
#: Local slope: least squares over this many neighbouring distances (one decade).
SLOPE_WINDOW = 5
#: The near-border range ends where the pooled local slope departs from its reference by more than this.
FLAT_REL = 0.02
#: The range scan: nested ranges from d_lo to every distance from SLOPE_WINDOW − 1 quarter decades (one decade)
#: above it up to the last; the ranges inside the near-border range give the range systematic.
SCAN_MIN_POINTS = SLOPE_WINDOW
#: The alternative estimator of the sides' λ at the quoted range: the mean without this fraction at either end.
TRIM = 0.1
#: Borders per window, lines per window and points per line (full run, quick run).
N_BORDERS = (32, 2)
N_LINES = (16, 2)
LINE_POINTS = (64, 24)
#: Border rates against the friction: the `physical` die with its pivot's slip coefficient c = μ m g / v_reg moved,
#: through v_reg and through μ (v_reg 20 and μ 0.6 share one c: only c enters the linearisation), each setting's
#: near-border λ against its own slipping-pivot root.  Borders per window (full, quick), the profile's distances
#: (1e-11 … 1e-6) and the widths (decades above d_lo) of the nested fit ranges.
FRICTION = {"v_reg 2.5": {"v_reg_cm_s": 2.5}, "v_reg 5": {"v_reg_cm_s": 5.0}, "v_reg 20": {"v_reg_cm_s": 20.0},
            "v_reg 40": {"v_reg_cm_s": 40.0}, "μ 0.6": {"mu": 0.6}}
FRICTION_BORDERS, FRICTION_LINES, FRICTION_POINTS = (8, 1), (8, 2), (48, 16)
FRICTION_DISTS = DISTS[:21]
FRICTION_WIDTHS = (1.0, 1.5, 2.0, 2.5, 3.0)


def _config(opts: dict, tol: float | None = None):
    kw = dict(opts)
    if tol is not None:
        kw["tol"] = tol
    return make_config(kw.pop("preset"), **kw)


def _lines(ranges, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """``n`` chords of the window: half from the left to the right edge, half from the bottom to the top, at
    random heights (positions) at both ends."""
    (x0, x1), (y0, y1) = ranges
    starts, ends = [], []
    for i in range(n):
        u, v = rng.uniform(0, 1, 2)
        if i % 2 == 0:
            starts.append((x0, y0 + u * (y1 - y0)))
            ends.append((x1, y0 + v * (y1 - y0)))
        else:
            starts.append((x0 + u * (x1 - x0), y0))
            ends.append((x0 + v * (x1 - x0), y1))
    return np.array(starts), np.array(ends)


def _borders(ctx: Context, cfg, window: str):
    """Located borders of one window: (brackets, crossings found)."""

    classify = classify_on_slice("seed", config=cfg)
    starts, ends = _lines(window_ranges(window), ctx.pick(*N_LINES), ctx.rng)
    pairs = line_crossings(classify, starts, ends, ctx.pick(*LINE_POINTS))
    n = min(ctx.pick(*N_BORDERS), len(pairs))
    pick = ctx.rng.choice(len(pairs), size=n, replace=False)
    br = bisect_many(classify, [pairs[i] for i in pick], tol=BISECT_WIDTH)
    ctx.n_throws += classify.n_evals
    return br, len(pairs)


def _concat(brs):
    return Brackets(*(np.concatenate([getattr(b, f) for b in brs]) for f in
                      ("p_lo", "p_hi", "label_lo", "label_hi", "width")), sum(b.n_evals for b in brs))


def _join_profiles(profs):
    return {k: np.concatenate([p[k] for p in profs]) for k in profs[0]}


def _corner_rate(cfg):
    return corner_balance(config=cfg).rate


def sample_preset(ctx: Context, key: str) -> dict:
    """The raw measurements of one preset: located borders (brackets, windows, crossings found per window), the
    settle-time profiles at the tolerance and at a tenth of it, and the bracket ends classified at a tenth."""

    cfg, chk = _config(MODELS[key]), _config(MODELS[key], CHECK_TOL)
    brs, found, win_of = [], {}, []
    for w in WINDOWS:
        br, found[w] = _borders(ctx, cfg, w)
        brs.append(br)
        win_of += [w] * len(br.p_lo)
    br = _concat(brs)
    settle, settle_chk = settle_on_slice("seed", config=cfg), settle_on_slice("seed", config=chk)
    classify_chk = classify_on_slice("seed", config=chk)
    prof, check = profiles(settle, br, DISTS), profiles(settle_chk, br, DISTS)
    ends = np.asarray(classify_chk(np.concatenate([br.p_lo, br.p_hi]))).ravel()
    ctx.n_throws += settle.n_evals + settle_chk.n_evals + classify_chk.n_evals
    return {"br": br, "windows": np.array(win_of), "found": found, "prof": prof, "check": check,
            "ends_check": ends, "cfg": cfg, "chk": chk}


def raw_frame(key: str, raw: dict):
    """The raw measurements of one preset as a long table: one row per border, side and distance."""

    br, n = raw["br"], len(raw["br"].p_lo)
    rows = []
    for side, lab in (("lo", br.label_lo), ("hi", br.label_hi)):
        end_chk = raw["ends_check"][:n] if side == "lo" else raw["ends_check"][n:]
        for i in range(n):
            for j, d in enumerate(DISTS):
                rows.append((key, i, raw["windows"][i], side, br.p_lo[i, 0], br.p_lo[i, 1], br.p_hi[i, 0],
                             br.p_hi[i, 1], int(lab[i]), int(end_chk[i]), float(d),
                             int(raw["prof"][f"label_{side}"][i, j]), float(raw["prof"][f"t_{side}"][i, j]),
                             int(raw["check"][f"label_{side}"][i, j]), float(raw["check"][f"t_{side}"][i, j])))
    return pd.DataFrame(rows, columns=RAW_COLUMNS)


#: Columns of ``results/raw/border_rates_profiles.csv``: the border (its bracket ends, window), the side (its
#: label and its bracket end's label at tol/10), the distance, and the label and settle time at tol and at tol/10.
RAW_COLUMNS = ["model", "border", "window", "side", "lo_x", "lo_y", "hi_x", "hi_y", "side_label",
               "end_label_check", "d", "label", "t_settle_s", "label_check", "t_settle_check_s"]


def raw_from_frame(df, key: str) -> dict:
    """:func:`sample_preset`'s arrays of one preset back from :func:`raw_frame`'s table (without the configs and
    the crossings found)."""

    q = df[df.model == key].sort_values(["side", "border", "d"], key=lambda c: c.map({"lo": 0, "hi": 1})
                                        if c.name == "side" else c)
    nd = len(DISTS)
    lo, hi = q[q.side == "lo"], q[q.side == "hi"]
    n = len(lo) // nd
    first_lo, first_hi = lo.iloc[::nd], hi.iloc[::nd]
    p_lo = first_lo[["lo_x", "lo_y"]].to_numpy(float)
    p_hi = first_lo[["hi_x", "hi_y"]].to_numpy(float)
    br = Brackets(p_lo, p_hi, first_lo.side_label.to_numpy(), first_hi.side_label.to_numpy(),
                  np.linalg.norm(p_hi - p_lo, axis=1), 0)

    def grid(frame, col):
        return frame[col].to_numpy().reshape(n, nd)

    prof = {"label_lo": grid(lo, "label"), "label_hi": grid(hi, "label"), "t_lo": grid(lo, "t_settle_s"),
            "t_hi": grid(hi, "t_settle_s")}
    check = {"label_lo": grid(lo, "label_check"), "label_hi": grid(hi, "label_check"),
             "t_lo": grid(lo, "t_settle_check_s"), "t_hi": grid(hi, "t_settle_check_s")}
    ends = np.concatenate([first_lo.end_label_check.to_numpy(), first_hi.end_label_check.to_numpy()])
    return {"br": br, "windows": first_lo.window.to_numpy(), "prof": prof, "check": check, "ends_check": ends}


def analyse_preset(raw: dict, numerics: dict, found: dict, *, seed: int = 0) -> dict:
    """Every number of one preset from its raw measurements (:func:`sample_preset`): the stability at tol/10, the
    flat range, the fits near the border and over the whole range, their errors, the analytic rates."""

    br, prof, check = raw["br"], raw["prof"], raw["check"]
    n = len(br.p_lo)
    ends_changed = np.concatenate([raw["ends_check"][:n] != br.label_lo, raw["ends_check"][n:] != br.label_hi])
    ends = {"n_ends": 2 * n, "n_changed": int(ends_changed.sum()), "fraction_changed": float(ends_changed.mean()),
            "n_borders_moved": int(np.sum(ends_changed[:n] | ends_changed[n:]))}
    stab = tolerance_stability(DISTS, br, prof, check, t_res=numerics["dt_s"])
    if stab["d_min"] is None:
        raise RuntimeError(f"{numerics['preset']}: no distance is stable at tol/10")
    want = np.concatenate([br.label_lo, br.label_hi])
    t = np.concatenate([prof["t_lo"], prof["t_hi"]])
    got = np.concatenate([prof["label_lo"], prof["label_hi"]])
    ok = (got == want[:, None]) & (DISTS[None, :] >= stab["d_min"])
    slopes, d_mid = local_slopes(DISTS, t, ok, window=SLOPE_WINDOW)
    first = stab["start"]  # the first window of stable points
    flat = flat_range(d_mid, slopes, rel=FLAT_REL, start=min(first, len(d_mid) - 1))
    d_lo = stab["d_min"]
    d_hi = flat["d_max"] if flat["d_max"] is not None else float(DISTS[min(first + SLOPE_WINDOW, len(DISTS) - 1)])
    rng = np.random.default_rng(seed)

    def summary(lams):
        return border_bootstrap(lams, n, seed=int(rng.integers(2**31)))

    near_l = fit_sides(DISTS, br, prof, d_lo, d_hi)
    near = summary(near_l)
    limit = _range_limit(br, prof, check, d_lo, d_hi, n, np.random.default_rng([seed, 1]))  # its own stream
    alt_check = summary(fit_sides(DISTS, br, check, d_lo, d_hi))
    alt_short = summary(fit_sides(DISTS, br, prof, d_lo, max(d_hi / 10, d_lo * 10 ** 0.75)))
    all_l = fit_sides(DISTS, br, prof, d_lo, DISTS[-1])
    whole = summary(all_l)
    syst = max(abs(a.get("median", near["median"]) - near["median"]) for a in (alt_check, alt_short))
    near.update(syst=syst, total=math.hypot(near["median_stderr"] or 0.0, syst), d_lo=d_lo, d_hi=d_hi)
    whole.update(d_lo=d_lo, d_hi=float(DISTS[-1]))
    cfg = _config(MODELS[numerics["preset"]])
    saddle = edge_saddle(config=cfg)
    limit.update(minus_edge=limit["value"] - saddle.rate,
                 z_edge=one_sided_z(limit["value"], limit["stat"], limit["syst_lo_total"], limit["syst_hi_total"],
                                    saddle.rate))
    by_window = {}
    sides_win = np.concatenate([raw["windows"], raw["windows"]])
    for w in WINDOWS:
        sel = sides_win == w
        lam, lam_all = np.where(sel, near_l, np.nan), np.where(sel, all_l, np.nan)
        has, has_all = np.isfinite(lam).any(), np.isfinite(lam_all).any()
        by_window[w] = {"n_crossings": found.get(w), "n_borders": int(sel.sum() // 2),
                        "near_median": float(np.nanmedian(lam)) if has else None,
                        "near_q25": float(np.nanquantile(lam, 0.25)) if has else None,
                        "near_q75": float(np.nanquantile(lam, 0.75)) if has else None,
                        "all_median": float(np.nanmedian(lam_all)) if has_all else None}
    return {
        "numerics": numerics,
        "analytic": {"edge": saddle.rate, "edge_rigid": saddle.rate_rigid, "edge_free": saddle.rate_free,
                     "slip_c": saddle.slip_c if math.isfinite(saddle.slip_c) else None, "corner": _corner_rate(cfg)},
        "n_borders": n, "bisect_max_width": float(br.width.max()), "ends": ends,
        "stability": {"flips": stab["flips"], "n_sides": stab["n_sides"], "median_abs_dt": stab["median_abs_dt"],
                      "d_min": d_lo, "t_res": stab["t_res"], "flips_total": int(stab["flips"].sum()),
                      "flips_from_d_min": int(stab["flips"][first:].sum())},
        "flat": {"reference_slope": flat["reference_slope"], "reference_rate": 1.0 / flat["reference_slope"],
                 "rel": FLAT_REL, "window": SLOPE_WINDOW, "d_max": d_hi, "median_slope": flat["median_slope"],
                 "count": flat["count"], "d_mid": d_mid, "q25_slope": _nanq(slopes, 0.25),
                 "q75_slope": _nanq(slopes, 0.75)},
        "limit": limit, "near": near, "near_check_tol": alt_check, "near_short": alt_short, "all_range": whole,
        "near_minus_edge": near["median"] - saddle.rate,
        "near_z_edge": (near["median"] - saddle.rate) / near["total"] if near["total"] else None,
        "all_minus_edge": whole["median"] - saddle.rate,
        "by_window": by_window, "lambdas_near": near_l, "lambdas_all": all_l,
    }


def _range_limit(br, prof, check, d_lo: float, d_hi: float, n: int, rng) -> dict:
    """λ (median over sides, bootstrap error over borders) fitted over nested ranges from ``d_lo`` to every distance
    from one decade above it to the last (:func:`~dicetrace.analysis.robustness.range_scan`): the shortest range's
    λ, the limit as the range shrinks, with the ranges inside the near-border range ``d_hi`` and the straight-line
    extrapolation to zero width as its one-sided range systematic; beside it, the shift at that range when the
    profiles integrated at tol/10 are fitted instead (tolerance) and when the sides' λ are pooled by their trimmed
    mean instead of their median (estimator: each side's λ over a decade is quantised by the settle time's 1 ms
    resolution, which the median keeps), each on both sides in quadrature with the range's."""
    from scipy.stats import trim_mean

    i0 = int(np.argmin(np.abs(np.log(DISTS / d_lo))))
    his = DISTS[i0 + SCAN_MIN_POINTS - 1:]
    ranges = [(float(d_lo), float(h)) for h in his]
    n_in = max(1, int(np.sum(his <= d_hi * (1 + 1e-9))))
    seeds = iter(rng.integers(2**31, size=len(ranges)))

    def fit(lo, hi):
        b = border_bootstrap(fit_sides(DISTS, br, prof, lo, hi), n, seed=int(next(seeds)))
        return b.get("median", math.nan), b.get("median_stderr")

    scan = range_scan(fit, ranges, syst_over=n_in, extrapolate=True)
    lo, hi = ranges[0]
    at_check = fit_sides(DISTS, br, check, lo, hi)
    at = fit_sides(DISTS, br, prof, lo, hi)
    tol_shift = float(np.nanmedian(at_check)) - scan.value
    est_shift = float(trim_mean(at[np.isfinite(at)], TRIM)) - scan.value
    out = scan.as_dict()
    out.update(d_lo=lo, d_hi=hi, syst_d_hi=ranges[n_in - 1][1], near_d_hi=float(d_hi), tol_shift=tol_shift,
               estimator_shift=est_shift, trim=TRIM,
               syst_lo_total=math.sqrt(scan.syst_lo**2 + min(tol_shift, 0.0)**2 + min(est_shift, 0.0)**2),
               syst_hi_total=math.sqrt(scan.syst_hi**2 + max(tol_shift, 0.0)**2 + max(est_shift, 0.0)**2))
    out["syst_total"] = max(out["syst_lo_total"], out["syst_hi_total"])
    out["syst_dominates_total"] = bool(out["syst_total"] > (out["stat"] or 0.0))
    out["text"] = stat_syst(scan.value, scan.stat, scan.syst_lo, scan.syst_hi)
    out["note"] = syst_note(scan.stat, scan.syst, "fit-range")
    return out


def _numerics(key: str, cfg, chk) -> dict:
    return {"preset": key, "integrator": cfg.numerics.integrator, "tol": cfg.numerics.tol,
            "tol_growth": cfg.numerics.tol_growth, "check_tol": chk.numerics.tol, "dt_s": cfg.numerics.dt_s,
            "bisect_width": BISECT_WIDTH}


def _nanq(a, q: float) -> np.ndarray:
    """The ``q`` quantile of each column of ``a`` over its finite values (NaN for a column without any)."""
    a = np.asarray(a, float)
    return np.array([np.quantile(c[np.isfinite(c)], q) if np.isfinite(c).any() else np.nan for c in a.T])


def compute(ctx: Context) -> Computed:
    results, plot = {"windows": list(WINDOWS), "dists": DISTS}, {}
    for key in MODELS:
        raw = sample_preset(ctx, key)
        seed = int(ctx.rng.integers(2**31))
        r = results[key] = analyse_preset(raw, _numerics(key, raw["cfg"], raw["chk"]), raw["found"], seed=seed)
        r.update(bootstrap_seed=seed, bisect_n_evals=raw["br"].n_evals)
        plot[key] = raw
        ctx.log(f"{key}: {r['n_borders']} borders, ends changed at tol/10 {r['ends']['n_changed']}/"
                f"{r['ends']['n_ends']}, stable from d = {r['near']['d_lo']:.1e}, flat to {r['near']['d_hi']:.1e}; "
                f"λ near {r['near']['median']:.2f} ± {r['near']['total']:.2f}, all-range "
                f"{r['all_range']['median']:.2f}, edge saddle {r['analytic']['edge']:.2f} /s")
    results["friction"] = friction_sweep(ctx, None if not ctx.quick else dict(list(FRICTION.items())[-2:-1]))
    results["friction_summary"] = friction_summary(results)
    return Computed(results, plot)


def friction_sweep(ctx: Context, settings: dict | None = None) -> dict:
    """Each FRICTION setting of the `physical` die at the uniform tolerance: borders of home and zoom-out bisected to
    BISECT_WIDTH, their settle-time profiles at FRICTION_DISTS at the tolerance and a tenth of it, the smallest
    stable distance d_lo (:func:`~dicetrace.analysis.border_rates.tolerance_stability`), and λ over nested ranges from
    d_lo (:func:`~dicetrace.analysis.robustness.range_scan`: the shortest range quoted, the others as its one-sided
    range systematic) against the setting's slipping-pivot root (:func:`edge_saddle`), with the one-sided z."""
    rng = np.random.default_rng([ctx.options.seed, 44])  # its own stream: the presets' numbers do not move
    out = {}
    for name, over in (settings or FRICTION).items():
        opts = {**MODELS["physical"], **over}
        cfg, chk = _config(opts), _config(opts, CHECK_TOL)
        classify, settle = classify_on_slice("seed", config=cfg), settle_on_slice("seed", config=cfg)
        settle_chk = settle_on_slice("seed", config=chk)
        brs = []
        for w in WINDOWS:
            starts, ends = _lines(window_ranges(w), ctx.pick(*FRICTION_LINES), rng)
            pairs = line_crossings(classify, starts, ends, ctx.pick(*FRICTION_POINTS))
            pick = rng.choice(len(pairs), size=min(ctx.pick(*FRICTION_BORDERS), len(pairs)), replace=False)
            brs.append(bisect_many(classify, [pairs[i] for i in pick], tol=BISECT_WIDTH))
        br = _concat(brs)
        prof, check = profiles(settle, br, FRICTION_DISTS), profiles(settle_chk, br, FRICTION_DISTS)
        ctx.n_throws += classify.n_evals + settle.n_evals + settle_chk.n_evals
        saddle = edge_saddle(config=cfg)
        row = {"setting": name, "overrides": over, "mu": cfg.preset.mu, "v_reg_cm_s": cfg.preset.v_reg_cm_s,
               "slip_c": saddle.slip_c, "edge": saddle.rate, "edge_rigid": saddle.rate_rigid,
               "edge_free": saddle.rate_free, "n_borders": int(len(br.p_lo)), **_friction_fit(br, prof, check, rng)}
        if row.get("value") is not None:
            row["minus_edge"] = row["value"] - saddle.rate
            row["z_edge"] = one_sided_z(row["value"], row["stat"], row["syst_lo"], row["syst_hi"], saddle.rate)
            row["z_rigid"] = one_sided_z(row["value"], row["stat"], row["syst_lo"], row["syst_hi"], saddle.rate_rigid)
        out[name] = row
        ctx.log(f"friction {name} (c = {saddle.slip_c:.1f}): {row['n_borders']} borders, d_lo {row.get('d_lo')}, λ "
                f"{row.get('text')} against the slipping pivot's {saddle.rate:.2f} /s (z {row.get('z_edge')})")
    return out


def _friction_fit(br, prof, check, rng) -> dict:
    """One friction setting's λ from its profiles: d_lo, and the range scan from it (module docstring)."""
    n = len(br.p_lo)
    stab = tolerance_stability(FRICTION_DISTS, br, prof, check, t_res=1e-3)
    if stab["d_min"] is None:
        return {"d_lo": None, "value": None, "error": "no distance is stable at tol/10"}
    d_lo = stab["d_min"]
    ranges = [(d_lo, d_lo * 10**w) for w in FRICTION_WIDTHS if d_lo * 10**w <= FRICTION_DISTS[-1] * (1 + 1e-9)]
    if not ranges:
        return {"d_lo": d_lo, "value": None, "error": "no fit range above the stable distance"}
    seeds = iter(rng.integers(2**31, size=len(ranges)))

    def fit(lo, hi):
        b = border_bootstrap(fit_sides(FRICTION_DISTS, br, prof, lo, hi), n, seed=int(next(seeds)))
        return b.get("median", math.nan), b.get("median_stderr")

    try:
        scan = range_scan(fit, ranges)
    except ValueError as e:
        return {"d_lo": d_lo, "value": None, "error": str(e)}
    out = scan.as_dict()
    out.update(d_lo=d_lo, flips=int(stab["flips"].sum()), text=stat_syst(scan.value, scan.stat, scan.syst_lo,
                                                                          scan.syst_hi))
    return out


def _letter() -> str:
    return {v: k for k, v in LETTERS.items()}.get(NAME, "x")


#: Each preset's colour in the figures.
COLOURS = {"seed": "tab:blue", "physical": "tab:red"}


def _draw_local_slope(ax, key: str, r: dict) -> None:
    """One preset's panel of the local rate against the distance from the border."""
    f = r["flat"]
    dm, med = np.asarray(f["d_mid"], float), np.asarray([math.nan if v is None else v for v in f["median_slope"]])
    with np.errstate(divide="ignore", invalid="ignore"):
        ax.semilogx(dm, 1.0 / med, "o-", ms=3, color=COLOURS[key], label="1 / pooled local slope")
        q25, q75 = (np.asarray(f[q], float) for q in ("q25_slope", "q75_slope"))
        ax.fill_between(dm, 1.0 / q75, 1.0 / q25,
                        color=COLOURS[key], alpha=0.15, label="interquartile range of the sides")
    ax.axhline(r["analytic"]["edge"], color="k", lw=1, label=f"edge saddle {r['analytic']['edge']:.2f} /s")
    if r["analytic"].get("corner"):
        ax.axhline(r["analytic"]["corner"], color="k", ls=":", lw=1,
                   label=f"corner balance {r['analytic']['corner']:.2f} /s")
    ax.axhline(r["all_range"]["median"], color="0.5", ls="--", lw=1,
               label=f"all-range fits, median {r['all_range']['median']:.2f} /s")
    if r["near"].get("d_hi"):
        ax.axvspan(r["near"]["d_lo"], r["near"]["d_hi"], color="0.85", zorder=0, label="near-border fit range")
    ax.set_ylim(15, 45)
    ax.set_title(f"{key}: contact-tsit5, uniform tol {r['numerics']['tol']:g}", fontsize=10)
    ax.set_xlabel("distance d from the border (slice units)")


def _draw_range(ax, key: str, r: dict) -> None:
    """One preset's panel of λ against the width of the fit range (the range scan)."""
    lim = r["limit"]
    w = np.asarray(lim["widths"], float)
    v = np.asarray([math.nan if x is None else x for x in lim["values"]], float)
    e = np.asarray([math.nan if x is None else x for x in lim["stderrs"]], float)
    k = lim["n_syst"]
    ax.errorbar(w[:k], v[:k], yerr=e[:k], fmt="o", ms=4, color=COLOURS[key], label="inside the near-border range")
    ax.errorbar(w[k:], v[k:], yerr=e[k:], fmt="o", ms=4, mfc="none", color=COLOURS[key], label="beyond it")
    inside = np.isfinite(v[:k])
    if lim.get("extrapolated") is not None and lim.get("trend") is not None and inside.sum() >= 2:
        ww = np.array([0.0, w[k - 1]])
        ax.plot(ww, lim["extrapolated"] + lim["trend"] * ww, ":", color=COLOURS[key],
                label=f"extrapolated to w = 0: {lim['extrapolated']:.2f} /s")
    ax.axhspan(lim["value"] - lim["syst_lo"], lim["value"] + lim["syst_hi"], color=COLOURS[key], alpha=0.12,
               label=f"shortest range {lim['value']:.2f} /s, range systematic")
    ax.axhline(r["analytic"]["edge"], color="k", lw=1, label=f"edge saddle {r['analytic']['edge']:.2f} /s")
    ax.set_xlim(0, None)
    ax.set_ylim(r["analytic"]["edge"] - 0.6, r["analytic"]["edge"] + 1.4)
    ax.set_title(f"{key}: λ against the fit range from d_lo = {lim['d_lo']:.1e}", fontsize=10)
    ax.set_xlabel("width of the fit range w (decades of d)")


def friction_summary(R: dict) -> dict:
    """The friction sweep's verdict from its rows and the `physical` preset's own (v_reg 10): how many settings
    agree with their slipping-pivot root (|z| < 2), disagree (|z| > 3), and the range of the roots spanned."""
    rows = [dict(v, setting=k) for k, v in R["friction"].items() if v.get("value") is not None]
    ph = R["physical"]
    rows.append({"setting": "v_reg 10 (the preset)", "edge": ph["analytic"]["edge"], "value": ph["limit"]["value"],
                 "z_edge": ph["limit"]["z_edge"]})
    z = [abs(r["z_edge"]) for r in rows if r.get("z_edge") is not None and math.isfinite(r["z_edge"])]
    n_ok, n_bad = sum(v < 2 for v in z), sum(v > 3 for v in z)
    verdict = ("supported" if z and n_ok == len(z) else "refuted" if n_bad else "undetermined")
    return {"n_settings": len(rows), "n_consistent": n_ok, "n_inconsistent": n_bad, "verdict": verdict,
            "edge_min": min(r["edge"] for r in rows), "edge_max": max(r["edge"] for r in rows),
            "value_min": min(r["value"] for r in rows), "value_max": max(r["value"] for r in rows),
            "failed": [k for k, v in R["friction"].items() if v.get("value") is None],
            "failed_text": ", ".join(f"{k} ({v.get('error')})" for k, v in R["friction"].items()
                                     if v.get("value") is None) or "none",
            "failed_d_lo": [v.get("d_lo") for v in R["friction"].values() if v.get("value") is None],
            "same_c": _same_c(rows)}


def _same_c(rows: list[dict]) -> list[dict]:
    """Groups of settings that reach one slip coefficient by different means (v_reg and μ): their λ side by side."""
    by: dict = {}
    for r in rows:
        if "slip_c" in r:
            by.setdefault(round(r["slip_c"], 6), []).append(r)
    return [{"slip_c": c, "settings": [r["setting"] for r in g], "values": [r["value"] for r in g]}
            for c, g in by.items() if len(g) > 1]


def _friction_render(R: dict, out: Output, letter: str) -> None:
    """The friction sweep's table and figure (measured against predicted λ, each setting)."""
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing

    rows = []
    for name, v in R["friction"].items():
        rows.append({"s": name, "mu": v["mu"], "v": v["v_reg_cm_s"], "c": v["slip_c"], "edge": v["edge"],
                     "n": v["n_borders"], "dlo": fmt(v.get("d_lo"), ".1e"),
                     "lam": v.get("text") or f"– ({v.get('error')})", "z": v.get("z_edge"), "zr": v.get("z_rigid")})
    ph = R["physical"]
    rows.insert(0, {"s": "v_reg 10 (the preset; above)", "mu": 1.2, "v": 10.0, "c": ph["analytic"]["slip_c"],
                    "edge": ph["analytic"]["edge"], "n": ph["n_borders"], "dlo": f"{ph['limit']['d_lo']:.1e}",
                    "lam": ph["limit"]["text"], "z": ph["limit"]["z_edge"], "zr": None})
    out.tables["friction"] = md_table(rows, [
        ("s", "setting", ""), ("mu", "μ", "g"), ("v", "v_reg (cm/s)", "g"), ("c", "slip coefficient c", ".1f"),
        ("edge", "slipping-pivot root (1/s)", ".2f"), ("n", "borders", "d"), ("dlo", "d_lo", ""),
        ("lam", "λ near the border, shortest range (1/s)", ""), ("z", "z vs its root", ".1f"),
        ("zr", "z vs the held pivot", ".1f")])
    fig, ax = plt.subplots(figsize=(5.6, 4.6))
    pts = [(r["edge"], R["friction"][r["s"]] if r["s"] in R["friction"] else None, r) for r in rows]
    for edge, v, r in pts:
        if v is None:
            val, st, lo, hi = ph["limit"]["value"], ph["limit"]["stat"], ph["limit"]["syst_lo"], ph["limit"]["syst_hi"]
        elif v.get("value") is None:
            continue
        else:
            val, st, lo, hi = v["value"], v["stat"] or 0.0, v["syst_lo"], v["syst_hi"]
        ax.errorbar([edge], [val], yerr=[[math.hypot(st, lo)], [math.hypot(st, hi)]], fmt="o", capsize=3)
        ax.annotate(r["s"].split(" (")[0], (edge, val), textcoords="offset points", xytext=(5, -10), fontsize=7)
    lo_, hi_ = 22.0, max(p[0] for p in pts) + 2.0
    ax.plot([lo_, hi_], [lo_, hi_], "k-", lw=0.8, label="measured = slipping-pivot root")
    ax.axhline(R["seed"]["analytic"]["edge_rigid"], color="0.5", ls=":", lw=1, label="held pivot")
    ax.set_xlabel("slipping-pivot root of the setting (1/s)")
    ax.set_ylabel("λ near the border (1/s)")
    ax.set_title("border rates against the friction (physical, contact-tsit5 1e-13)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    out.save_fig(fig, f"{letter}_friction", key="friction", caption=(
        "λ near the border (shortest fit range, bars: statistical and range errors in quadrature) of the `physical` "
        "die with its friction's slip coefficient c = μ m g / v_reg moved through v_reg and μ, against each setting's "
        "slipping-pivot root from the linearisation (docs/model.md, \"Balances linearised\"); line: equality."))


def _signed(v: float) -> str:
    """A shift with its sign, to two decimals (no negative zero)."""
    return f"{v:+.2f}".replace("-0.00", "+0.00")


def range_table(R: dict) -> str:
    """λ against the width of the fit range, both presets side by side (every half decade, and the ranges that end
    the systematic and the near-border range)."""
    rows = {}
    for key in MODELS:
        lim = R[key]["limit"]
        for i, (w, v, e) in enumerate(zip(lim["widths"], lim["values"], lim["stderrs"])):
            half = abs(w * 2 - round(w * 2)) < 1e-6
            if not half and i != lim["n_syst"] - 1:
                continue
            row = rows.setdefault(round(w, 2), {"w": w})
            row[key] = pm(v, e, ".2f") + (" (syst.)" if i < lim["n_syst"] else "")
            row[f"{key}_d"] = f"{lim['ranges'][i][1]:.1e}"
    return md_table([rows[k] for k in sorted(rows)], [
        ("w", "range width (decades above d_lo)", ".2f"), ("seed_d", "`seed`: up to d", ""),
        ("seed", "`seed`: λ (1/s)", ""), ("physical_d", "`physical`: up to d", ""),
        ("physical", "`physical`: λ (1/s)", "")])


def _draw_lambdas(ax, key: str, r: dict) -> None:
    """One preset's panel of the histograms of every side's λ, near the border and over the whole range."""
    near = np.asarray(r["lambdas_near"], float)
    whole = np.asarray(r["lambdas_all"], float)
    bins = np.linspace(15, 45, 61)
    ax.hist(near[np.isfinite(near)], bins=bins, color=COLOURS[key], alpha=0.7,
            label=f"near the border: {pm(r['near']['median'], r['near']['total'], '.2f')} /s")
    ax.hist(whole[np.isfinite(whole)], bins=bins, histtype="step", color="k",
            label=f"whole range: {pm(r['all_range']['median'], r['all_range']['median_stderr'], '.2f')} /s")
    ax.axvline(r["analytic"]["edge"], color="k", lw=1.5, label=f"edge saddle {r['analytic']['edge']:.2f} /s")
    ax.set_title(f"{key}: λ of every side ({r['near']['n_sides']} sides)", fontsize=10)
    ax.set_xlabel("λ / (1/s)")


def _save_by_preset(out: Output, results: dict, draw, name: str, key: str, *, height: float, ylabel: str,
                    caption: str, sharey: bool = True) -> None:
    """A figure of one panel a preset side by side on one y axis: ``draw(ax, preset, its results)`` fills each
    (title and x label too), then each gets a legend and the first the y label."""
    import matplotlib.pyplot as plt  # heavy optional library: imported only when drawing

    fig, axes = plt.subplots(1, len(MODELS), figsize=(12, height), sharey=sharey)
    for ax, preset in zip(axes, MODELS):
        draw(ax, preset, results[preset])
        ax.legend(fontsize=7)
    axes[0].set_ylabel(ylabel)
    fig.tight_layout()
    out.save_fig(fig, name, key=key, caption=caption)


def render(c: Computed, out: Output) -> None:
    R, L = c.results, _letter()
    if c.plot:  # a fresh run: its raw measurements, from which :func:`rerender` recomputes every number
        (out.res_dir / Path(RAW_CSV).parent).mkdir(parents=True, exist_ok=True)
        out.write_csv(pd.concat([raw_frame(k, c.plot[k]) for k in MODELS], ignore_index=True), RAW_CSV)
    _save_by_preset(out, R, _draw_local_slope, f"{L}_local_slope", "local_slope", height=4.4,
                    ylabel="local rate 1 / (dT/d(−ln d)) / (1/s)",
                    caption="The local rate 1/(dT/d(−ln d)) of the settle time against the distance from the border "
                    "(least squares over a sliding decade, median over every side of every border of home and "
                    "zoom-out; band: interquartile range). Grey: the near-border fit range (stable at tol/10, slope "
                    "within 2 % of its value at the smallest stable distances).")
    _save_by_preset(out, R, _draw_range, f"{L}_range", "range", height=4.2, ylabel="λ (1/s), median over sides",
                    caption="λ fitted from the smallest stable distance d_lo to d_lo·10^w against the width w of the "
                    "range (decades; median over every side, bootstrap error over borders). Filled: the ranges inside "
                    "the near-border range (local slope within 2 %), which give the range systematic; line: their "
                    "straight-line extrapolation to zero width; band: the shortest range's value with its one-sided "
                    "range systematic; black: the edge saddle.", sharey=False)
    _save_by_preset(out, R, _draw_lambdas, f"{L}_lambdas", "lambdas", height=4.0, ylabel="sides",
                    caption="λ of every side fitted near the border (filled) and over the whole range from the same "
                    "smallest distance to 1e-3 (outline), with the analytic edge saddle of each preset.")

    rows = []
    for key in MODELS:
        r = R[key]
        lim = r["limit"]
        rows.append({
            "model": key, "num": f"{r['numerics']['integrator']}, tol {r['numerics']['tol']:g} uniform",
            "edge": r["analytic"]["edge"], "corner": r["analytic"].get("corner"),
            "lrange": f"{lim['d_lo']:.0e} – {lim['d_hi']:.0e}",
            "limit": lim["value"], "stat": lim["stat"],
            "rsyst": f"+{lim['syst_hi']:.2f} / −{lim['syst_lo']:.2f}",
            "tol": _signed(lim["tol_shift"]), "est": _signed(lim["estimator_shift"]), "z": lim["z_edge"],
            "range": f"{r['near']['d_lo']:.0e} – {r['near']['d_hi']:.0e}" if r["near"].get("d_hi") else "–",
            "near": pm(r["near"]["median"], r["near"]["median_stderr"], ".2f"),
            "all": pm(r["all_range"]["median"], r["all_range"]["median_stderr"], ".2f"),
            "sides": f"{r['near']['n_sides']} ({r['n_borders']} borders)",
            "ends": f"{r['ends']['n_changed']}/{r['ends']['n_ends']}",
        })
    out.tables["rates"] = md_table(rows, [
        ("model", "model", ""), ("num", "numerics", ""), ("edge", "edge saddle (1/s)", ".2f"),
        ("corner", "corner balance (1/s)", ".2f"), ("lrange", "shortest range d", ""),
        ("limit", "λ, shortest range (1/s)", ".2f"), ("stat", "stat", ".2f"),
        ("rsyst", "range syst (+ / −)", ""), ("tol", "shift at tol/10", ""),
        ("est", "shift, trimmed mean", ""), ("z", "z vs edge saddle", ".1f"),
        ("range", "2 % range d", ""), ("near", "λ over the 2 % range (1/s)", ""),
        ("all", "λ whole range (1/s)", ""), ("sides", "sides", ""), ("ends", "bracket ends changed at tol/10", "")])
    out.tables["range"] = range_table(R)
    if R.get("friction"):
        _friction_render(R, out, L)
    rows = []
    for key in MODELS:
        for w, b in R[key]["by_window"].items():
            rows.append({"model": key, "window": w, "borders": b["n_borders"], "crossings": b["n_crossings"],
                         "near": b["near_median"], "iqr": f"{b['near_q25']:.2f}–{b['near_q75']:.2f}"
                         if b["near_q25"] is not None else "–", "all": b["all_median"]})
    out.tables["windows"] = md_table(rows, [
        ("model", "model", ""), ("window", "window", ""), ("borders", "borders", "d"),
        ("crossings", "crossings found", "d"), ("near", "median λ near (1/s)", ".2f"),
        ("iqr", "interquartile range", ""), ("all", "median λ whole range (1/s)", ".2f")])


def rerender(out) -> Path:
    """Recompute every number of a finished run in ``out`` from its raw measurements
    (``results/raw/border_rates_profiles.csv``) and redraw its figures and tables (no simulation; the figures take
    the study's letter as it is registered now); rewrites ``results/border_rates.json``."""


    out = Path(out)
    path = out / "results" / f"{NAME}.json"
    results = json.loads(path.read_text())
    df = pd.read_csv(out / "results" / f"{RAW_CSV}.csv")
    for key in MODELS:
        old = results[key]
        found = {w: b["n_crossings"] for w, b in old["by_window"].items()}
        new = analyse_preset(raw_from_frame(df, key), old["numerics"], found, seed=old["bootstrap_seed"])
        new.update(bootstrap_seed=old["bootstrap_seed"], bisect_n_evals=old.get("bisect_n_evals"))
        results[key] = new
    if results.get("friction"):  # derived from the sweep's rows and the preset's (just recomputed)
        results["friction_summary"] = friction_summary(results)
    output = Output(out)
    render(Computed(results), output)
    results["figures"], results["tables"] = output.figures, output.tables
    write_json(path, results)
    return path


def add_friction(out, options=None) -> Path:
    """Run the friction sweep (:func:`friction_sweep`, the full run's settings) into a finished run in ``out`` and
    redraw its tables and figures from the raw profiles (:func:`rerender`): the presets' numbers do not move (the sweep
    draws from its own random stream), so the results are those a full run gives.  Its time is kept in
    ``friction_s`` and added to ``wall_s``."""
    import time

    from dicetrace.studies.context import Options

    out = Path(out)
    path = out / "results" / f"{NAME}.json"
    results = json.loads(path.read_text())
    ctx = Context(NAME, options or Options(), out / "cache")
    t0 = time.perf_counter()
    results["friction"] = friction_sweep(ctx)
    results["friction_s"] = time.perf_counter() - t0
    results["friction_n_throws"] = int(ctx.n_throws)
    results["wall_s"] = results.get("wall_s", 0.0) + results["friction_s"]
    results["n_throws_simulated"] = results.get("n_throws_simulated", 0) + ctx.n_throws
    write_json(path, results)
    return rerender(out)
