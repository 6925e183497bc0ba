"""Study r (hazard_law): the hazard law of the edge saddle, κ_settle(t) = α(ε(t))·λ_edge, on 10⁵ throws per model.

Section n's test compared one late settle hazard with α at one scale; the law behind it says more: a throw
that starts ε from a border lingers −ln ε/λ_edge on the edge before it falls, so the throws still moving at t
are those within ε(t) = exp(−λ_edge (t − T0)) of a border, and the settle hazard at t is the local uncertainty
exponent at that scale times the saddle's rate, levelling off at λ_edge where the borders turn smooth (α → 1).
Per model (``seed`` with ``contact-tsit5``, and ``physical``; both at a uniform tolerance of 1e-10 as section n):

* N random ICs of the zoom-out window of the seed slice (L in the program's convention), as section n samples
  them; their settle hazard in windows between quantiles of the settle time up to the 99.97 % quantile
  (:func:`~dicetrace.analysis.doubly_transient.hazard_curve`, Poisson errors);
* f(ε) at half decades from a top scale down to 1e-12, from nested pairs: every base gets one random direction, its
  neighbour at the top scale is thrown for every base, and the finer neighbours on the same ray only for the bases
  whose top pair changed (:func:`~dicetrace.analysis.hazard_law.nested_f`), for ``physical`` at 1e-11 (bases and top
  pairs thrown again there); the *leak* (pairs that change at the next scale without changing at the top) is
  measured on a random sample of the others;
* the settle clock: the mean settle time of the bases whose pair changed at each scale, ``T0 + (D − ln ε)/λ_edge``
  with D the mean depth of those bases below ε read off f itself
  (:func:`~dicetrace.analysis.hazard_law.settle_clock`, :func:`~dicetrace.analysis.hazard_law.log_depth`), its T0
  over nested ranges of scales (the finest three first, :func:`~dicetrace.analysis.robustness.range_scan`), and the
  free slope's rate beside λ_edge;
* the law window by window: the measured hazard against α (the secant slope of ln f over the window's scales)
  times λ_edge, with the clock's systematic (its T0 over the ranges of scales, ± its error, and the clock's own free
  slope and intercept in place of λ_edge's) and the tolerance systematic; its verdict;
* certificates at 1e-11 (10× tighter): every throw past the 88 % quantile of the settle time and a random sample of
  the rest (outcome flips, settle-time shifts, each window's hazard again), the nested pairs of the first changed
  bases at a tenth of their own tolerance (the floor of each scale: a scale counts where its 95 % bound is below a
  third of f and at least ten pairs changed) and the top pairs of the first bases.
"""

from __future__ import annotations

import math
import time

import numpy as np

from dicetrace.analysis.border_rates import edge_saddle
from dicetrace.analysis.doubly_transient import compare, floor_test, hazard_curve
from dicetrace.analysis.hazard_law import (along_rays, eps_of_t, law_verdict, law_window, levels_off, log_depth,
                                           nested_f, quantile_hazard, secant_alpha, settle_clock, unit_rays)
from dicetrace.analysis.robustness import one_sided_z, range_scan
from dicetrace.ics import seed_slice
from dicetrace.params import make_config
from dicetrace.studies.context import (Computed, Context, Output, jsonable, rerender_results,
                                       window_ranges)
from dicetrace.studies.study_hazard_law_render import render as _render

NAME = "hazard_law"
WINDOW = "zoom-out"
#: The uniform tolerance of every throw, and the certificate's (10× tighter).
TOL, TOL_TIGHT = 1e-10, 1e-11
#: model -> (preset, make_config overrides, top scale of the nested pairs, tolerance of the nested pairs).  The top
#: lies above the scales the tail past the 90 % quantile reaches on the settle clock (a trial of 3000 throws: about
#: 1e-8 for ``physical``, 1e-5 for ``seed``).  ``physical``'s nested pairs run at 1e-11 (their floor at 1e-12): at
#: 1e-10 its floor (24 of 11000 near-border throws change face at 1e-11) stops f at 3e-10, above the scales its tail
#: reaches; ``seed``'s floor at 1e-10 showed no change in 16000.
MODELS = {
    "seed": ("seed", {"integrator": "contact-tsit5"}, 1e-5, TOL),
    "physical": ("physical", {}, 10.0**-7.5, TOL / 10),
}
#: Finest scale of the nested pairs (half decades from the top down to it).
FINEST = 1e-12
#: Base ICs per model (full run, quick run) and the quick run's scales below the top (decades).
N_FULL, N_QUICK = 100_000, 1500
QUICK_DECADES = 3
#: Quantiles of the settle time that bound the hazard's windows; the law is tested from TAIL_FROM on.
QUANTILES = (0.5, 0.75, 0.9, 0.95, 0.97, 0.98, 0.99, 0.995, 0.998, 0.999, 0.9997)
TAIL_FROM = 0.9
#: A scale counts where the floor's 95 % bound is below this share of f and at least MIN_CHANGED pairs changed.
FLOOR_SHARE, MIN_CHANGED = 1.0 / 3.0, 10
#: Certificates: throws past this quantile all rerun at TOL_TIGHT, with CERT_RANDOM (quick) earlier ones; the nested
#: pairs of the first CERT_NESTED changed bases; the top pairs of the first CERT_TOP bases; LEAK bases that did not
#: change at the top, thrown at the next scale.
CERT_FROM = 0.88
CERT_RANDOM = (2000, 100)
CERT_NESTED = (1000, 40)
CERT_TOP = (2000, 200)
LEAK = (10_000, 300)
#: Batches are thrown in chunks of this many (a log line each).
CHUNK = 50_000


def _config(model: str, tol: float):
    preset, over = MODELS[model][:2]
    return make_config(preset, tol=tol, tol_growth=0.0, **over)


def _numerics(cfg) -> dict:
    p, n = cfg.preset, cfg.numerics
    return {"preset": p.name, "gamma": p.gamma, "k": p.k, "integrator": n.integrator, "tol": n.tol,
            "tol_growth": n.tol_growth}


def scales(top: float, quick: bool) -> np.ndarray:
    """The nested scales, ascending, the top last: half decades down to FINEST (quick: whole decades, three)."""
    lt = math.log10(top)
    if quick:
        return 10.0 ** np.arange(lt - QUICK_DECADES, lt + 0.01, 1.0)
    return 10.0 ** np.arange(lt - round(2 * (lt - math.log10(FINEST))) / 2, lt + 0.01, 0.5)


def _throw(ctx: Context, ics: np.ndarray, cfg, what: str):
    """(outcome, settle time) of every row, thrown in chunks of CHUNK."""
    from dicetrace.simulate import simulate_batch  # lazy: numba

    outs, ts = [], []
    t = time.perf_counter()
    for a in range(0, len(ics), CHUNK):
        b = simulate_batch(ics[a:a + CHUNK], config=cfg)
        outs.append(np.asarray(b.outcome, dtype=np.int64))
        ts.append(np.asarray(b.t_settle_s, dtype=float))
        ctx.n_throws += len(ics[a:a + CHUNK])
        if len(ics) > CHUNK:
            ctx.log(f"  {what}: {min(a + CHUNK, len(ics))}/{len(ics)} throws ({time.perf_counter() - t:.0f} s)")
    return np.concatenate(outs), np.concatenate(ts)


def _measure(ctx: Context, model: str, index: int) -> dict:
    t_start = time.perf_counter()
    cfg, tight = _config(model, TOL), _config(model, TOL_TIGHT)
    top = MODELS[model][2]
    eps = scales(top, ctx.quick)
    n = ctx.pick(N_FULL, N_QUICK)
    rng = np.random.default_rng([ctx.options.seed, 44, index])
    (x0, x1), (y0, y1) = window_ranges(WINDOW)
    ics = cfg.to_preset_convention(np.asarray(seed_slice(rng.uniform(x0, x1, n), rng.uniform(y0, y1, n))), "program")
    rays = unit_rays(n, ics.shape[1], rng)
    lam = edge_saddle(config=cfg).rate

    # the base throws and their top pairs
    o, ts = _throw(ctx, np.concatenate([ics, along_rays(ics, rays, top)]), cfg, "bases and top pairs")
    o0, o_top, t_base = o[:n], o[n:], ts[:n]
    settled = o0 >= 1
    t_cap = cfg.numerics.t_max_s
    life = np.where(settled & np.isfinite(t_base), t_base, t_cap)
    censored = ~settled
    valid_top = settled & (o_top >= 1)
    c_top = valid_top & (o_top != o0)
    idx = np.flatnonzero(c_top)
    ctx.log(f"{model}: {n} bases, {int(censored.sum())} unsettled, {len(idx)} pairs changed at the top ε {top:.2g}")

    # nested pairs below the top, on the changed bases, at the model's nested tolerance (the bases and their top pairs
    # thrown again there where it is tighter than TOL; a row whose top pair no longer changes there counts as invalid)
    ntol = MODELS[model][3]
    ncfg = _config(model, ntol)
    fine = eps[:-1]
    moved = [along_rays(ics[idx], rays[idx], e) for e in fine]
    if ntol != TOL:
        moved += [ics[idx], along_rays(ics[idx], rays[idx], top)]
    o_n, _ = _throw(ctx, np.concatenate(moved) if len(idx) else np.zeros((0, 6)), ncfg, "nested pairs")
    o_n = o_n.reshape(len(moved), len(idx))
    nb, ntop = (o_n[-2], o_n[-1]) if ntol != TOL else (o0[idx], o_top[idx])
    o_n = o_n[:len(fine)].T
    top_kept = (ntop != nb) & (ntop >= 1) & (nb >= 1)
    changed = np.column_stack([o_n != nb[:, None], np.ones(len(idx), bool)])
    valid = np.column_stack([o_n >= 1, np.ones(len(idx), bool)]) & (top_kept | (ntol == TOL))[:, None]
    n_bases = int(valid_top.sum())
    nf = nested_f(changed, eps, n_bases, valid=valid, n_boot=ctx.pick(400, 60), rng=rng)

    # the leak: bases unchanged at the top, thrown at the next scale on their ray
    others = np.flatnonzero(valid_top & ~c_top)
    m = min(ctx.pick(*LEAK), len(others))
    leak_idx = rng.choice(others, m, replace=False)
    o_l, _ = _throw(ctx, along_rays(ics[leak_idx], rays[leak_idx], fine[-1]), cfg, "leak pairs")
    leak_changed = int(((o_l >= 1) & (o_l != o0[leak_idx])).sum())
    leak_f = leak_changed / max(m, 1) * len(others) / max(n_bases, 1)
    leak = {"scale": float(fine[-1]), "pairs": int(m), "changed": leak_changed, "f_leak": leak_f,
            "share": leak_f / (leak_f + nf.f[-2]) if leak_f + nf.f[-2] > 0 else math.nan,
            "hi95": float(floor_test(np.arange(m)[:, None] < leak_changed, np.zeros((m, 1), bool))["hi"][0])
            * len(others) / max(n_bases, 1) if m else math.nan}

    # floors at TOL_TIGHT: the top pairs of the first bases, the nested pairs of the first changed bases
    k_top = min(ctx.pick(*CERT_TOP), n)
    ot, _ = _throw(ctx, np.concatenate([ics[:k_top], along_rays(ics[:k_top], rays[:k_top], top)]), tight, "top floor")
    vt = valid_top[:k_top] & (ot[:k_top] >= 1) & (ot[k_top:] >= 1)
    top_fl = floor_test(c_top[:k_top][:, None], (ot[:k_top] != ot[k_top:])[:, None], valid=vt[:, None])
    k_n = min(ctx.pick(*CERT_NESTED), len(idx))
    sub = idx[:k_n]
    mv = np.concatenate([ics[sub]] + [along_rays(ics[sub], rays[sub], e) for e in eps])
    on, _ = _throw(ctx, mv, _config(model, ntol / 10), "nested floor")
    on = on.reshape(len(eps) + 1, k_n)
    ch_t = (on[1:] != on[0]).T
    v_t = ((on[1:] >= 1) & (on[0] >= 1)).T & valid[:k_n]
    nest_fl = floor_test(changed[:k_n], ch_t, valid=v_t)
    # two bounds on the pairs whose verdict flips at a scale, as shares of all bases: the flipped pairs of the
    # subsample (95 % Wilson bound) and twice the share of its throws whose face changes (a pair flips only where one
    # of its throws does), each scaled by the share of bases in the nested set
    thr = (on != np.concatenate([nb[:k_n][None], o_n[:k_n].T, ntop[:k_n][None]])) & (on >= 1)
    thr_fl = floor_test(thr.ravel()[:, None], np.zeros((thr.size, 1), bool))
    share = len(idx) / max(n_bases, 1)
    pair_bound = np.asarray(nest_fl["hi"], float) * share
    throw_bound = 2.0 * float(thr_fl["hi"][0]) * share if thr.size else 1.0
    floor_bound = np.minimum(np.where(np.isfinite(pair_bound), pair_bound, 1.0), throw_bound)
    counted = (floor_bound <= FLOOR_SHARE * nf.f) & (nf.changed >= MIN_CHANGED)

    # the settle clock on the counted scales
    t_mean, t_sem, t_med = [], [], []
    for k in range(len(eps)):
        tk = t_base[idx][changed[:, k] & valid[:, k]]
        t_mean.append(float(tk.mean()) if len(tk) else math.nan)
        t_sem.append(float(tk.std(ddof=1) / math.sqrt(len(tk))) if len(tk) > 1 else math.nan)
        t_med.append(float(np.median(tk)) if len(tk) else math.nan)
    t_mean, t_sem = np.array(t_mean), np.array(t_sem)
    ce = eps[counted]
    clock, clock_scan, t0_values = None, None, []
    depth = np.full(len(eps), np.nan)
    if counted.sum() >= 2:
        depth[counted] = log_depth(ce, nf.changed[counted])
        clock = settle_clock(ce, t_mean[counted], t_sem[counted], lam, depth[counted])

        def fit(lo, hi):
            sel = counted & (eps >= lo * (1 - 1e-9)) & (eps <= hi * (1 + 1e-9))
            c = settle_clock(eps[sel], t_mean[sel], t_sem[sel], lam, depth[sel])
            return c.t0, c.t0_stderr

        k0 = min(2, len(ce) - 1)
        ranges = [(float(ce[0]), float(ce[j])) for j in range(k0, len(ce))]
        clock_scan = range_scan(fit, ranges).as_dict()
        t0_values = [v for v in clock_scan["values"] if v is not None]
    t0 = clock_scan["value"] if clock_scan else math.nan

    # the hazard in quantile windows, and the same windows at TOL_TIGHT on the tail's throws
    hz, edges = quantile_hazard(life, QUANTILES, censored=censored)
    q_cert = float(np.quantile(life, CERT_FROM))
    late = np.flatnonzero(life >= q_cert)
    early = np.flatnonzero(life < q_cert)
    rnd = rng.choice(early, min(ctx.pick(*CERT_RANDOM), len(early)), replace=False)
    cert_idx = np.concatenate([late, rnd])
    oc, tc = _throw(ctx, ics[cert_idx], tight, "tail at tol/10")
    flips = int(((oc != o0[cert_idx]) & settled[cert_idx]).sum())
    life_t = life.copy()
    life_t[cert_idx] = np.where(oc >= 1, tc, t_cap)
    cen_t = censored.copy()
    cen_t[cert_idx] = oc < 1
    hz_t = hazard_curve(life_t, edges, censored=cen_t)
    both = settled[cert_idx] & (oc >= 1)
    dt = np.abs(tc[both] - t_base[cert_idx][both])
    crossed = int(((life_t[rnd] >= edges[2]) & (life[rnd] < q_cert)).sum())
    cert = {"tol": TOL_TIGHT, "from_quantile": CERT_FROM, "from_s": q_cert, "late": int(len(late)),
            "random": int(len(rnd)), "outcome_flips": flips, "thrown": int(len(cert_idx)),
            "dt_median_s": float(np.median(dt)) if len(dt) else math.nan,
            "dt_q99_s": float(np.quantile(dt, 0.99)) if len(dt) else math.nan,
            "dt_max_s": float(dt.max()) if len(dt) else math.nan, "random_crossing_q90": crossed,
            "h_tight": hz_t.h.tolist(), "h_tight_stderr": hz_t.stderr.tolist()}

    # the law, window by window
    windows = []
    for j in range(len(hz.h)):
        h, se = float(hz.h[j]), float(hz.stderr[j])
        w = law_window(h, se, float(hz.t0[j]), float(hz.t1[j]), nf, t0, lam, counted=counted)
        w.update(q0=QUANTILES[j], q1=QUANTILES[j + 1], events=int(hz.events[j]), tail=QUANTILES[j] >= TAIL_FROM - 1e-9)
        tol_syst = abs(float(hz_t.h[j]) - h) if math.isfinite(hz_t.h[j]) else math.nan
        preds = []
        clocks = [(tv, lam) for tv in t0_values + ([t0 - clock_scan["stat"], t0 + clock_scan["stat"]]
                                                    if clock_scan else [])]
        if clock is not None and math.isfinite(clock.lam_fit):  # the clock's own slope and intercept
            clocks.append((clock.t0_fit, clock.lam_fit))
        for tv, lc in clocks:
            try:
                preds.append(secant_alpha(nf, float(eps_of_t(w["t1"], tv, lc)), float(eps_of_t(w["t0"], tv, lc)),
                                          counted=counted)[0] * lam)
            except ValueError:
                continue
        if w["pred"] is not None:
            lo = max([0.0] + [w["pred"] - p for p in preds])
            hi = max([0.0] + [p - w["pred"] for p in preds])
            err_meas = math.hypot(se, tol_syst if math.isfinite(tol_syst) else 0.0)
            z = -one_sided_z(w["pred"], w["pred_err"] if math.isfinite(w["pred_err"]) else 0.0, lo, hi, h, err_meas)
            verdict = "consistent" if abs(z) < 2 else "inconsistent" if abs(z) > 3 else "undetermined"
        else:
            lo = hi = math.nan
            z, verdict = math.nan, "undetermined"
        w.update(tol_syst=tol_syst, clock_syst_lo=lo, clock_syst_hi=hi, z_stat=w.pop("z"), z=z, verdict=verdict)
        w.pop("x", None), w.pop("y", None), w.pop("x_err", None), w.pop("y_err", None)
        windows.append(w)
    tail = [w for w in windows if w["tail"]]
    verdict = law_verdict([w["z"] for w in tail])
    lev = levels_off([w["h"] for w in tail], [w["h_err"] for w in tail], lam)
    lev_from = tail[lev["from_window"]] if lev["from_window"] is not None else None
    # where the borders turn smooth: the largest scale below which every counted local slope is within 2σ of 1
    both_c = counted[:-1] & counted[1:] & np.isfinite(nf.slope_stderr)
    alpha1 = None
    for j in np.flatnonzero(both_c):  # finest first
        if abs(nf.slope[j] - 1.0) < 2 * nf.slope_stderr[j]:
            alpha1 = float(nf.eps_mid[j])
        else:
            break
    clock_check = compare(clock.lam_fit, clock.lam_fit_stderr, lam, 0.0) if clock else compare(*(math.nan,) * 4)
    row = {
        "model": model, **_numerics(cfg), "tight_tol": TOL_TIGHT, "nested_tol": ntol, "window": WINDOW, "n": n,
        "unsettled": int(censored.sum()), "edge_saddle": lam, "top": float(top),
        "settle_quantiles": {str(q): float(np.quantile(life, q)) for q in (0.5, 0.9, 0.99, 0.999, 0.9997)},
        "settle_max_s": float(life[settled].max()),
        "f": {**nf.as_dict(), "counted": counted.tolist(), "floor_bound": floor_bound.tolist(),
              "floor_flips": np.asarray(nest_fl["flips"]).tolist(), "floor_pairs": np.asarray(nest_fl["n"]).tolist(),
              "floor_throw_flips": int(thr.sum()), "floor_throws": int(thr.size), "floor_pair_bound": pair_bound.tolist(),
              "floor_throw_bound": throw_bound,
              "top_floor_flips": int(top_fl["flips"][0]), "top_floor_pairs": int(top_fl["n"][0]),
              "top_changed": int(len(idx)), "n_bases": n_bases, "leak": leak,
              "finest_counted": float(ce[0]) if len(ce) else math.nan,
              "t_mean": t_mean.tolist(), "t_sem": t_sem.tolist(), "t_median": t_med, "depth": depth.tolist()},
        "clock": clock.as_dict() if clock else None, "clock_scan": clock_scan, "t0": t0, "clock_check": clock_check,
        "windows": windows, "certificate": cert, "verdict": verdict, "levels_off": lev,
        "levels_off_from_s": lev_from["t0"] if lev_from else None,
        "levels_off_from_q": lev_from["q0"] if lev_from else None,
        "last_window_vs_edge": compare(tail[-1]["h"], tail[-1]["h_err"], lam, 0.0) if tail else None,
        "alpha_one_below": alpha1, "wall_s": time.perf_counter() - t_start,
    }
    ctx.log(f"{model}: f counted down to {row['f']['finest_counted']:.1e}, T0 {t0:.3f} s, clock λ "
            f"{clock.lam_fit if clock else math.nan:.1f} vs edge {lam:.2f} /s; law {verdict['verdict']} "
            f"({verdict['n_windows']} windows, max |z| {verdict['max_abs_z']:.1f}); {row['wall_s']:.0f} s")
    return row


def derived(row: dict) -> dict:
    """Numbers the report quotes, derived from a row's stored f alone (a pure function, applied again by
    :func:`rerender`): ``f_at`` (f at 1e-9 and 1e-8 where those scales were thrown), and the counted local slopes
    between the two finest counted scales (``slope_finest``) and the two coarsest (``slope_top``), with stderrs."""
    f = row["f"]
    eps = np.asarray(f["eps"], dtype=float)
    f_at = {}
    for key, e in (("1e-9", 1e-9), ("1e-8", 1e-8)):
        k = np.flatnonzero(np.isclose(eps, e, rtol=1e-6, atol=0.0))
        f_at[key] = float(f["f"][k[0]]) if len(k) else None
    cnt = np.asarray(f["counted"], dtype=bool)
    both = np.flatnonzero(cnt[:-1] & cnt[1:])
    pick = {"finest": both[0] if len(both) else None, "top": both[-1] if len(both) else None}
    out = {"f_at": f_at}
    for key, j in pick.items():
        out[f"slope_{key}"] = f["slope"][j] if j is not None else None
        out[f"slope_{key}_stderr"] = f["slope_stderr"][j] if j is not None else None
    return out


def compute(ctx: Context) -> Computed:
    rows = [_measure(ctx, m, i) for i, m in enumerate(MODELS)]
    for row in rows:
        row["derived"] = jsonable(derived(row))
    return Computed({"rows": rows, "by": {r["model"]: r for r in rows}, "window": WINDOW, "tol": TOL,
                     "tight_tol": TOL_TIGHT, "quantiles": list(QUANTILES), "tail_from": TAIL_FROM,
                     "finest": FINEST, "floor_share": FLOOR_SHARE, "min_changed": MIN_CHANGED})


def render(c: Computed, out: Output) -> None:
    _render(c, out)


def rerender(out) -> dict:
    """Draw the figures and tables again from ``OUT/results/hazard_law.json`` alone and write them back into it (no
    simulation, no measured number changed; :func:`derived` is applied again)."""
    def derive(r):
        for row in r["rows"]:  # a pure function of the stored f: derived again with the code
            row["derived"] = jsonable(derived(row))
        r["by"] = {row["model"]: row for row in r["rows"]}

    return rerender_results(out, NAME, render, derive)
