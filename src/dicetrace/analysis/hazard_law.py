"""The hazard law of an edge saddle, κ_settle(t) = α_local(ε(t))·λ_edge: the measures that test it.

A throw whose initial condition lies a relative distance ε from a border between two faces balances on an
edge before it falls; linearised about the balance, the tilt grows like ``exp(λ_edge t)``, so the throw lingers
``−ln ε / λ_edge`` longer than one far from the border.  Its settle time is ``t ≈ T0 − ln ε / λ_edge`` (the
*settle clock*, :func:`settle_clock`), so the throws still moving at ``t`` are those within
``ε(t) = exp(−λ_edge (t − T0))`` of a border (:func:`eps_of_t`).  Their share is the uncertainty fraction
``f(ε(t))`` (pairs ε apart whose faces differ), so the survival is ``S(t) ∝ f(ε(t))`` and the settle hazard
``κ(t) = −d ln S / dt = α_local(ε(t))·λ_edge``, with ``α_local = d ln f / d ln ε``.  Where the borders are smooth
(α → 1) the hazard levels off at λ_edge; where they are fractal (α < 1) it lies below.

* :func:`quantile_hazard`: the settle hazard in closed windows between quantiles of the settle times (events over
  time at risk, Poisson errors);
* :func:`unit_rays`, :func:`along_rays`: one random direction per base point and its neighbours along it at
  every scale (nested pairs: the same ray at every ε);
* :func:`nested_f`: ``f(ε)`` at fine scales from nested pairs, evaluated only on the bases whose pair at the top
  scale changed (a pair along the ray can change at a finer scale without changing at the top only where the
  segment crosses a border twice: the *leak*, measured apart); its local slopes with a Poisson bootstrap of the
  bases;
* :func:`secant_alpha`: the mean local slope of ``ln f`` between two scales (``ln f`` piecewise linear in
  ``ln ε`` between measured scales): the α a window of time sees;
* :func:`settle_clock`: ``T0`` of the settle clock from the mean settle time of the bases whose pair changed at
  each scale, the slope fixed at λ_edge, and the free slope's rate beside it; those bases lie on average
  :func:`log_depth` e-folds below the scale (``1/α`` for a power law), which it corrects for;
* :func:`law_window`: one window of time, its measured hazard against ``secant_alpha(ε(t1), ε(t0))·λ_edge``;
* :func:`levels_off`: from which window on the hazard, pooled, is consistent with λ_edge.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .doubly_transient import Hazard, compare, hazard_curve

__all__ = ["quantile_hazard", "unit_rays", "along_rays", "NestedF", "nested_f", "log_f_at", "secant_alpha",
           "log_depth", "SettleClock", "settle_clock", "eps_of_t", "law_window", "levels_off", "law_verdict"]


def quantile_hazard(lifetimes, quantiles, *, censored=None) -> tuple[Hazard, np.ndarray]:
    """The hazard in closed windows between successive ``quantiles`` of the lifetimes (of the uncensored ones), with
    the window edges (s): :func:`~dicetrace.analysis.doubly_transient.hazard_curve`, events over time at risk in each
    window with the Poisson error ``h/√events``.  Tied quantiles are moved apart by 1e-12 so that every window has a
    width."""
    t = np.asarray(lifetimes, dtype=float).ravel()
    cen = np.zeros(len(t), bool) if censored is None else np.asarray(censored, dtype=bool).ravel()
    edges = np.quantile(t[~cen] if (~cen).any() else t, np.asarray(quantiles, dtype=float))
    edges = np.maximum.accumulate(edges + np.arange(len(edges)) * 1e-12)
    return hazard_curve(t, edges, censored=cen), edges


def unit_rays(n: int, dim: int, rng) -> np.ndarray:
    """``n`` random unit vectors of ``dim`` dimensions (uniform on the sphere)."""
    u = np.random.default_rng(rng).standard_normal((int(n), int(dim)))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def along_rays(ics, rays, eps: float) -> np.ndarray:
    """The ICs moved by ``eps · |ic| · ray`` (one unit ray per row): the neighbour at scale ``eps`` on each ray."""
    ics = np.asarray(ics, dtype=float)
    return ics + float(eps) * np.linalg.norm(ics, axis=1, keepdims=True) * np.asarray(rays, dtype=float)


@dataclasses.dataclass(frozen=True)
class NestedF:
    """``f(ε)`` from nested pairs (:func:`nested_f`): the scales (ascending; the last is the top), the changed counts,
    the bases counted per scale, ``f`` with its binomial stderr, the local slopes between neighbouring scales (at their
    geometric means ``eps_mid``) with bootstrap stderrs, and the bootstrap counts ``boot`` (n_boot, scales) that
    :func:`secant_alpha` uses for its errors."""

    eps: np.ndarray
    changed: np.ndarray
    n: np.ndarray
    f: np.ndarray
    f_stderr: np.ndarray
    eps_mid: np.ndarray
    slope: np.ndarray
    slope_stderr: np.ndarray
    boot: np.ndarray

    def as_dict(self) -> dict:
        """JSON-able, without the bootstrap counts."""
        return {k: getattr(self, k).tolist() for k in ("eps", "changed", "n", "f", "f_stderr", "eps_mid", "slope",
                                                       "slope_stderr")}


def _log_slopes(counts: np.ndarray, leps: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        lc = np.where(counts > 0, np.log(np.maximum(counts, 1e-300)), np.nan)
    return np.diff(lc, axis=-1) / np.diff(leps)


def nested_f(changed, eps, n_bases: int, *, valid=None, n_boot: int = 400, rng=0) -> NestedF:
    """``f(ε)`` from nested pairs on the bases whose pair changed at the top scale.

    ``changed`` (n_top, scales): base i's pair along its ray differs at scale s; ``eps`` ascending, its last scale
    the top (every row changed there).  ``n_bases``: all the bases with a valid throw (the top's denominator);
    ``valid`` (same shape): both throws of the pair settled.  ``f = changed / (n_bases − invalid)``.  The errors of the
    slopes resample the changed bases with Poisson weights (the unchanged ones add nothing below the top); the
    slopes do not depend on ``n_bases``.  ValueError on shapes, on scales that do not ascend or a top scale where some
    row did not change."""
    c = np.asarray(changed, dtype=bool)
    eps = np.asarray(eps, dtype=float).ravel()
    if c.ndim != 2 or c.shape[1] != len(eps) or len(eps) < 2:
        raise ValueError(f"changed must be (n_top, {len(eps)}) with at least 2 scales, got shape {c.shape}")
    if not np.all(eps > 0) or np.any(np.diff(eps) <= 0):
        raise ValueError("eps must be positive and ascending (the top scale last)")
    v = np.ones_like(c) if valid is None else np.asarray(valid, dtype=bool)
    if len(c) and not np.all(c[:, -1] | ~v[:, -1]):
        raise ValueError("every nested row must have changed at the top scale (the last)")
    cv = (c & v).astype(np.float64)
    counts = cv.sum(axis=0)
    n = float(n_bases) - (~v).sum(axis=0)
    f = counts / np.maximum(n, 1.0)
    f_se = np.sqrt(f * (1 - f) / np.maximum(n, 1.0))
    leps = np.log(eps)
    slope = _log_slopes(counts, leps)
    w = np.random.default_rng(rng).poisson(1.0, size=(int(n_boot), len(c))).astype(np.float64)
    boot = w @ cv
    sb = _log_slopes(boot, leps)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(sb).mean(axis=0) >= 0.9 if len(sb) else np.zeros(len(slope), bool)
        se = np.full(len(slope), np.nan)
        for j in np.flatnonzero(ok & np.isfinite(slope)):
            col = sb[:, j][np.isfinite(sb[:, j])]
            se[j] = float(np.std(col, ddof=1)) if len(col) > 1 else math.nan
    return NestedF(eps, counts.astype(np.int64), n.astype(np.int64), f, f_se,
                   np.exp(leps[:-1] + np.diff(leps) / 2), slope, se, boot)


def log_f_at(eps, counts, x: float) -> float:
    """``ln counts`` interpolated linearly in ``ln ε`` at ``x`` (``ln f`` up to the constant ``ln n``); ValueError
    outside the scales or where a scale it needs has no change."""
    eps, counts = np.asarray(eps, float), np.asarray(counts, float)
    if not eps[0] <= x <= eps[-1]:
        raise ValueError(f"ε = {x:.3g} lies outside the measured scales {eps[0]:.3g}…{eps[-1]:.3g}")
    k = min(max(int(np.searchsorted(eps, x, side="right")) - 1, 0), len(eps) - 2)
    a, b = counts[k], counts[k + 1]
    if a <= 0 or b <= 0:
        raise ValueError(f"no change at a scale next to ε = {x:.3g}")
    s = (math.log(x) - math.log(eps[k])) / (math.log(eps[k + 1]) - math.log(eps[k]))
    return (1 - s) * math.log(a) + s * math.log(b)


def secant_alpha(nf: NestedF, lo: float, hi: float, *, counted=None) -> tuple[float, float]:
    """The mean local slope of ``ln f`` between the scales ``lo < hi`` (``ln f`` piecewise linear in ``ln ε``) and
    its bootstrap stderr.  Only the ``counted`` scales (a mask; default all with a change) are used: ValueError where
    ``lo``…``hi`` leaves them."""
    eps = nf.eps
    m = (nf.changed > 0) if counted is None else (np.asarray(counted, dtype=bool) & (nf.changed > 0))
    if m.sum() < 2:
        raise ValueError("fewer than two counted scales")
    e, c = eps[m], nf.changed[m]
    if not (lo < hi):
        raise ValueError("lo must be below hi")
    d = math.log(hi) - math.log(lo)
    a = (log_f_at(e, c, hi) - log_f_at(e, c, lo)) / d
    vals = []
    for row in nf.boot[:, m]:
        try:
            vals.append((log_f_at(e, row, hi) - log_f_at(e, row, lo)) / d)
        except ValueError:
            continue
    se = float(np.std(vals, ddof=1)) if len(vals) >= max(0.9 * len(nf.boot), 2) else math.nan
    return float(a), se


def log_depth(eps, counts) -> np.ndarray:
    """How far below each scale the throws changed there lie, on average: ``D(ε) = E[ln(ε/d) | d < ε]``
    ``= ∫₀^∞ f(ε e^{−u}) / f(ε) du``, with ``ln f`` piecewise linear in ``ln ε`` between the scales (ascending, counts
    all positive) and, below the finest, continued with the finest slope.  For ``f = ε^α`` it is ``1/α`` at every
    scale.  NaN where the finest slope is not positive."""
    e, c = np.asarray(eps, dtype=float).ravel(), np.asarray(counts, dtype=float).ravel()
    if len(e) < 2 or np.any(c <= 0) or np.any(np.diff(e) <= 0):
        raise ValueError("need two or more ascending scales, each with a change")
    x, lf = np.log(e), np.log(c)
    s = np.diff(lf) / np.diff(x)
    if s[0] <= 0:
        return np.full(len(e), np.nan)
    out = np.empty(len(e))
    for k in range(len(e)):
        total = math.exp(lf[0] - lf[k]) / s[0]  # below the finest scale
        for j in range(k):  # the segments between the finest scale and ε_k
            dx = x[j + 1] - x[j]
            seg = dx if abs(s[j] * dx) < 1e-12 else (math.exp(s[j] * dx) - 1.0) / s[j]
            total += math.exp(lf[j] - lf[k]) * seg
        out[k] = total
    return out


@dataclasses.dataclass(frozen=True)
class SettleClock:
    """``t ≈ T0 − ln d / λ`` for a throw a distance d from a border: ``T0`` (s) with its stderr for the slope fixed at
    ``lam`` (the edge saddle's rate), and the free slope's rate ``lam_fit`` (1/s) with its stderr, on the scales
    ``eps`` used, with the depth correction ``depth`` (:func:`log_depth`) of each; ``t0_fit``: the free line's ``T0``
    (its value at ε = 1)."""

    t0: float
    t0_stderr: float
    lam: float
    lam_fit: float
    lam_fit_stderr: float
    eps: np.ndarray
    depth: np.ndarray
    chi2_dof: float
    t0_fit: float = math.nan

    def as_dict(self) -> dict:
        return {"t0": self.t0, "t0_stderr": self.t0_stderr, "lam": self.lam, "lam_fit": self.lam_fit,
                "lam_fit_stderr": self.lam_fit_stderr, "t0_fit": self.t0_fit, "eps": self.eps.tolist(), "depth": self.depth.tolist(),
                "chi2_dof": self.chi2_dof}


def settle_clock(eps, t_mean, t_sem, lam: float, depth=None) -> SettleClock:
    """The settle clock from the mean settle time ``t_mean`` (± ``t_sem``) of the throws within each scale ``eps`` of
    a border (the bases whose pair changed there).  Those throws lie on average ``depth`` (:func:`log_depth`; 0 where
    None) e-folds below ε, so their mean settle time is ``T0 + (depth − ln ε)/lam``: ``T0`` is the weighted mean of
    ``t + (ln ε − depth)/lam``; beside it the weighted straight line ``t − depth/lam = a − b ln ε`` gives
    ``lam_fit = 1/b`` (NaN with fewer than three scales)."""
    e, t, s = (np.asarray(x, dtype=float).ravel() for x in (eps, t_mean, t_sem))
    dp = np.zeros(len(e)) if depth is None else np.asarray(depth, dtype=float).ravel()
    ok = np.isfinite(t) & np.isfinite(s) & (s > 0) & (e > 0) & np.isfinite(dp)
    e, t, s, dp = e[ok], t[ok], s[ok], dp[ok]
    if len(e) < 1:
        raise ValueError("no scale with a settle time")
    w = 1.0 / s**2
    y = t + (np.log(e) - dp) / lam
    t0 = float((w * y).sum() / w.sum())
    chi2 = float((w * (y - t0) ** 2).sum())
    dof = len(e) - 1
    t0_se = math.sqrt(1.0 / w.sum()) * (max(chi2 / dof, 1.0) ** 0.5 if dof > 0 else 1.0)
    lam_fit = lam_se = t0_fit = math.nan
    if len(e) >= 3:
        A = np.column_stack([np.ones_like(e), -np.log(e)])
        cov = np.linalg.inv(A.T @ (A * w[:, None]))
        coef = cov @ (A.T @ (w * (t - dp / lam)))
        res = t - dp / lam - A @ coef
        scale = max(float(res @ (w * res)) / (len(e) - 2), 1.0) if len(e) > 2 else 1.0
        b, b_se = float(coef[1]), math.sqrt(cov[1, 1] * scale)
        if b > 0:
            lam_fit, lam_se, t0_fit = 1.0 / b, b_se / b**2, float(coef[0])
    return SettleClock(t0, t0_se, float(lam), lam_fit, lam_se, e, dp, chi2 / dof if dof > 0 else math.nan, t0_fit)


def eps_of_t(t, t0: float, lam: float):
    """The scale the settle clock gives a throw still moving at ``t``: ``exp(−lam (t − t0))``."""
    return np.exp(-lam * (np.asarray(t, dtype=float) - t0))


def law_window(h: float, h_err: float, t_lo: float, t_hi: float, nf: NestedF, t0: float, lam: float, *,
               counted=None) -> dict:
    """One window ``[t_lo, t_hi)`` of the settle hazard ``h ± h_err`` against the law: ε runs from ``eps_of_t(t_lo)``
    down to ``eps_of_t(t_hi)``, α is :func:`secant_alpha` over it and the prediction ``α·lam``; the comparison is
    :func:`~dicetrace.analysis.doubly_transient.compare` (``consistent``/``inconsistent``/``undetermined``).  Where
    the window's scales leave the counted ones, α and the prediction are None and the verdict ``undetermined``."""
    e_hi, e_lo = float(eps_of_t(t_lo, t0, lam)), float(eps_of_t(t_hi, t0, lam))
    out = {"t0": float(t_lo), "t1": float(t_hi), "h": h, "h_err": h_err, "eps_hi": e_hi, "eps_lo": e_lo}
    try:
        a, a_se = secant_alpha(nf, e_lo, e_hi, counted=counted)
    except ValueError as e:
        out.update(alpha=None, alpha_stderr=None, pred=None, pred_err=None, why=str(e),
                   **compare(h, h_err, math.nan, math.nan))
        return out
    pred, pred_err = a * lam, a_se * lam
    out.update(alpha=a, alpha_stderr=a_se, pred=pred, pred_err=pred_err, **compare(h, h_err, pred, pred_err))
    return out


def levels_off(h, h_err, lam: float) -> dict:
    """Each window's hazard (``h ± h_err``, Poisson: ``events = (h/h_err)²``, windows earliest first) against ``lam``,
    and the first window from which the hazard has levelled off at it: the windows from there on pooled (their events
    over their time at risk) lie within 2σ of ``lam`` and none of them more than 3σ off (None where no window does).
    ``pooled_z``: the pooled z-score from each window on."""
    h, se = np.asarray(h, dtype=float), np.asarray(h_err, dtype=float)
    z = [compare(float(a), float(b), lam, 0.0)["z"] for a, b in zip(h, se)]
    with np.errstate(divide="ignore", invalid="ignore"):
        ev = np.where((h > 0) & (se > 0), (h / se) ** 2, np.nan)
    pooled = []
    for j in range(len(h)):
        e, x = ev[j:], ev[j:] / h[j:]
        if not np.all(np.isfinite(e)):
            pooled.append(math.nan)
            continue
        hp = e.sum() / x.sum()
        pooled.append((hp - lam) / (hp / math.sqrt(e.sum())))
    first = None
    for j in range(len(h)):
        if math.isfinite(pooled[j]) and abs(pooled[j]) < 2 and all(math.isfinite(v) and abs(v) <= 3 for v in z[j:]):
            first = j
            break
    return {"z": z, "pooled_z": pooled, "from_window": first}


def law_verdict(zs, *, min_windows: int = 3) -> dict:
    """The law's verdict over the tested windows' z-scores (NaN: not tested): ``refuted`` where a window lies more than
    3σ off, ``supported`` where at least ``min_windows`` are tested and all lie within 2σ, else ``undetermined``;
    with the χ² of the tested windows and its p-value."""
    from scipy import stats  # slow to import: only here

    z = np.array([v for v in zs if v is not None and math.isfinite(v)], dtype=float)
    chi2 = float((z**2).sum())
    p = float(stats.chi2.sf(chi2, len(z))) if len(z) else math.nan
    if len(z) and np.any(np.abs(z) > 3):
        verdict = "refuted"
    elif len(z) >= min_windows and np.all(np.abs(z) < 2):
        verdict = "supported"
    else:
        verdict = "undetermined"
    return {"verdict": verdict, "n_windows": int(len(z)), "chi2": chi2, "p_value": p,
            "max_abs_z": float(np.abs(z).max()) if len(z) else math.nan}
