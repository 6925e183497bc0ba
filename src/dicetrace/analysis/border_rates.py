"""The settle-time divergence at borders, fitted near the border, against the edge saddle of each preset.

An initial condition at distance ``d`` from a border (along a line that
crosses it) spends ``≈ −ln(d)/λ`` near the saddle whose stable manifold the
border is, so ``T(d) ≈ T0 − ln(d)/λ`` (:mod:`dicetrace.analysis.settle`).
The law holds only where the throw's departure from the saddle is linear:
farther out the approach to the saddle itself depends on ``d`` and the
local slope ``dT/d(−ln d)`` falls below ``1/λ``, so a fit over every
distance is biased upward.  This module measures where the slope is flat
and fits there:

* :func:`line_crossings` samples lines and keeps neighbouring points of
  different (settled) outcomes; :func:`bisect_many` bisects all of them in
  lock-step (one batch of throws per halving);
* :func:`profiles` samples the settle time at the distances ``d`` on both
  sides of every located border (one batch);
* :func:`local_slopes` and :func:`flat_range` give the local slope at each
  distance pooled over every side, and the largest distance up to which it
  stays within ``rel`` of its value at the smallest distances;
* :func:`fit_sides` fits ``T0 − ln(d)/λ`` on each side over a distance range,
  :func:`border_bootstrap` the median λ with a bootstrap error over borders;
* :func:`edge_saddle` is the analytic unstable rate of the edge balance of a
  configuration (held pivot for the program's friction law, slipping pivot
  for the per-node law).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from dicetrace.params import Config

from .settle import fit_settle_divergence
from .simulator import _resolve_config

__all__ = ["EdgeSaddle", "edge_saddle", "line_crossings", "Brackets", "bisect_many", "profiles", "local_slopes",
           "flat_range", "tolerance_stability", "fit_sides", "border_bootstrap", "end_flips"]

_M = 8.0  # the die's mass in node masses


@dataclasses.dataclass(frozen=True)
class EdgeSaddle:
    """The edge balance of one configuration, linearised (units: cm, s, node masses).

    ``rate``: the preset's unstable rate (1/s); ``rate_rigid``: held pivot,
    ``√(m g r / (I + m r²))``; ``rate_free``: frictionless floor, ``√(m g r / I)``;
    ``slip_c``: the pivot's linear friction coefficient (inf: held at first
    order); ``roots``: the roots of the planar characteristic polynomial.
    """

    preset: str
    friction: str
    r: float
    inertia: float
    rate_rigid: float
    rate_free: float
    rate: float
    slip_c: float
    roots: tuple[float, ...]


def edge_saddle(*, config: Config | None = None, preset: str = "seed", **overrides) -> EdgeSaddle:
    """The unstable rate of the die balanced on an edge, from the linearised planar motion.

    The centre of mass sits ``r = √2·half`` above the edge.  With its
    horizontal position ``X`` (normal to the edge) and the tilt ``θ``:
    ``m X'' = F`` and ``I θ'' = m g r θ − r F``, ``F`` the friction on the two
    pivot nodes.  The program's law ``μ P u/σ`` is of degree 0 in the
    velocities: a growing tilt meets a friction force of order ``μ P`` and the
    pivot is held at first order, ``λ = √(m g r / (I + m r²))``.  The
    per-node law is viscous well below ``v_reg``, ``F = −c (X' − r θ')`` with
    ``c = μ m g / v_reg`` summed over the two nodes, and the pivot slips:
    ``I m s³ + (I + m r²) c s² − m² g r s − m g r c = 0``, whose positive root
    lies between the held (``c → ∞``) and the free (``c → 0``) pivot.  The
    ground's compliance does not enter at first order (the normal force is
    vertical and the centre's height changes as θ²).
    """
    cfg = _resolve_config(config, preset, overrides)
    p = cfg.preset
    g, half, inertia = abs(float(p.g)), float(p.half_side_cm), float(p.inertia)
    r = math.sqrt(2.0) * half
    rigid = math.sqrt(_M * g * r / (inertia + _M * r * r))
    free = math.sqrt(_M * g * r / inertia)
    if p.friction == "spectral":
        c, roots, rate = math.inf, (-rigid, rigid), rigid
    else:
        c = float(p.mu) * _M * g / float(p.v_reg_cm_s)
        z = np.roots([inertia * _M, (inertia + _M * r * r) * c, -_M * _M * g * r, -_M * g * r * c])
        roots = tuple(sorted(float(v.real) for v in z))
        rate = max(roots)
    return EdgeSaddle(p.name, p.friction, r, inertia, rigid, free, float(rate), c, roots)


def line_crossings(classify, starts, ends, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Neighbouring points of different settled outcomes (labels > 0) on the segments ``starts[i] → ends[i]``,
    each sampled at ``n`` equally spaced points (one batch): a list of (p_a, p_b)."""
    starts, ends = np.atleast_2d(starts).astype(float), np.atleast_2d(ends).astype(float)
    t = np.linspace(0.0, 1.0, int(n))
    pts = starts[:, None, :] + t[None, :, None] * (ends - starts)[:, None, :]
    lab = np.asarray(classify(pts.reshape(-1, pts.shape[-1]))).reshape(pts.shape[:2])
    out = []
    for i in range(len(starts)):
        for j in range(int(n) - 1):
            if lab[i, j] > 0 and lab[i, j + 1] > 0 and lab[i, j] != lab[i, j + 1]:
                out.append((pts[i, j].copy(), pts[i, j + 1].copy()))
    return out


@dataclasses.dataclass(frozen=True)
class Brackets:
    """Located borders: ends ``p_lo`` (label of the segment's start) and ``p_hi`` (n, dim), their labels,
    widths, and the throws the bisection ran."""

    p_lo: np.ndarray
    p_hi: np.ndarray
    label_lo: np.ndarray
    label_hi: np.ndarray
    width: np.ndarray
    n_evals: int

    @property
    def midpoint(self) -> np.ndarray:
        return 0.5 * (self.p_lo + self.p_hi)

    @property
    def unit(self) -> np.ndarray:
        u = self.p_hi - self.p_lo
        return u / np.linalg.norm(u, axis=1, keepdims=True)


def bisect_many(classify, pairs, *, tol: float, max_iter: int = 200) -> Brackets:
    """Bisect every segment (p_a, p_b) of ``pairs`` (labels differ) until it is shorter than ``tol``, all in
    lock-step: one batch of the midpoints of the unfinished segments per halving.  As
    :func:`dicetrace.analysis.settle.bisect_boundary`: the low end keeps the label of ``p_a``, the high end
    takes the label of each midpoint that differs from it.  ValueError when the ends of a pair carry the same
    label."""
    a = np.array([np.asarray(p, float) for p, _ in pairs])
    b = np.array([np.asarray(q, float) for _, q in pairs])
    ends = np.asarray(classify(np.concatenate([a, b]))).ravel()
    la, lb = ends[: len(a)].copy(), ends[len(a):].copy()
    if np.any(la == lb):
        raise ValueError(f"{int(np.sum(la == lb))} pair(s) carry the same label at both ends")
    n_evals = 2 * len(a)
    lo, hi = a.copy(), b.copy()
    for _ in range(max_iter):
        mid = 0.5 * (lo + hi)
        todo = np.linalg.norm(hi - lo, axis=1) >= tol
        todo &= ~(np.all(mid == lo, axis=1) | np.all(mid == hi, axis=1))  # floating point cannot split further
        if not todo.any():
            break
        idx = np.nonzero(todo)[0]
        lm = np.asarray(classify(mid[idx])).ravel()
        n_evals += len(idx)
        same = lm == la[idx]
        lo[idx[same]] = mid[idx[same]]
        hi[idx[~same]] = mid[idx[~same]]
        lb[idx[~same]] = lm[~same]
    return Brackets(lo, hi, la, lb, np.linalg.norm(hi - lo, axis=1), n_evals)


def profiles(settle, br: Brackets, dists) -> dict[str, np.ndarray]:
    """Labels and settle times at ``midpoint ± d·unit`` for every border and distance (one batch): arrays
    ``label_lo``, ``t_lo`` (the ``p_lo`` side) and ``label_hi``, ``t_hi``, each (n_borders, n_dists)."""
    d = np.asarray(dists, float)
    mid, u = br.midpoint, br.unit
    out = {}
    pts = []
    for sign in (-1.0, 1.0):
        pts.append(mid[:, None, :] + sign * d[None, :, None] * u[:, None, :])
    P = np.concatenate(pts, axis=0)
    lab, t = settle(P.reshape(-1, P.shape[-1]))
    lab = np.asarray(lab).reshape(P.shape[:2])
    t = np.asarray(t, float).reshape(P.shape[:2])
    n = len(mid)
    out["label_lo"], out["label_hi"] = lab[:n], lab[n:]
    out["t_lo"], out["t_hi"] = t[:n], t[n:]
    return out


def _sides(br: Brackets, prof: dict):
    """(labels wanted, labels got, times) of every side: the lo sides then the hi sides, (2n, n_dists)."""
    want = np.concatenate([br.label_lo, br.label_hi])
    got = np.concatenate([prof["label_lo"], prof["label_hi"]])
    t = np.concatenate([prof["t_lo"], prof["t_hi"]])
    return want, got, t


def local_slopes(dists, t, ok, *, window: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """The local slope ``dT/d(−ln d)`` of each row of ``t``: least squares over ``window`` neighbouring distances
    (sliding; a window with a point that is not ``ok`` gives NaN), and the geometric-mean distance of each
    window: (slopes (rows, n − window + 1), d_mid (n − window + 1,)).  A window spanning a decade or more keeps
    the settle time's resolution (one output step) from the slope."""
    d = np.asarray(dists, float)
    x = -np.log(d)
    t = np.where(ok, np.asarray(t, float), np.nan)
    w = int(window)
    if w < 2 or w > len(d):
        raise ValueError(f"window must be in 2..{len(d)}, got {window}")
    n = len(d) - w + 1
    out = np.full((t.shape[0], n), np.nan)
    for j in range(n):
        xs = x[j:j + w] - x[j:j + w].mean()
        out[:, j] = (t[:, j:j + w] - t[:, j:j + w].mean(axis=1, keepdims=True)) @ xs / (xs @ xs)
    d_mid = np.exp(-np.array([x[j:j + w].mean() for j in range(n)]))
    return out, d_mid


def tolerance_stability(dists, br: Brackets, prof: dict, check: dict, *, t_res: float) -> dict:
    """How the profile changes when it is integrated again (``check``: :func:`profiles` with the tolerance
    tightened): at each distance, the verdicts that change and the median |ΔT| over the sides whose two verdicts
    are the side's label; ``d_min``: the smallest distance from which on no verdict changes and the median |ΔT|
    is at most ``t_res`` (s)."""
    want, got, t = _sides(br, prof)
    _, got2, t2 = _sides(br, check)
    flips = (got != got2).sum(axis=0)
    both = (got == want[:, None]) & (got2 == want[:, None])
    dt = np.where(both, np.abs(t - t2), np.nan)
    med = np.array([np.nanmedian(c) if np.isfinite(c).any() else np.nan for c in dt.T])
    good = (flips == 0) & (med <= t_res)
    start = len(good)
    while start > 0 and good[start - 1]:
        start -= 1
    d = np.asarray(dists, float)
    return {"flips": flips, "n_sides": int(len(want)), "median_abs_dt": med, "t_res": float(t_res),
            "d_min": float(d[start]) if start < len(d) else None, "start": int(start)}


def flat_range(d_mid, slopes, *, rel: float = 0.05, n_ref: int = 4, min_count: int = 5, start: int = 0) -> dict:
    """Where the pooled local slope is flat: from window ``start`` up to the last window before the first one at
    which the median slope over every side departs from the reference by more than ``rel`` of it.

    The reference is the median of the slopes of the ``n_ref`` windows from ``start`` on (pooled); a window with
    fewer than ``min_count`` finite slopes ends the range too.  Returns the reference slope, ``d_max`` (the
    ``d_mid`` of the last window inside; None when none is), ``end`` (the index of the first window outside;
    ``len(d_mid)`` when none is), and the median slope and its count at every window."""
    s = np.asarray(slopes, float)
    med = np.array([np.nanmedian(c) if np.isfinite(c).any() else np.nan for c in s.T])
    cnt = np.isfinite(s).sum(axis=0)
    ref_vals = s[:, start:start + n_ref]
    ref = float(np.nanmedian(ref_vals)) if np.isfinite(ref_vals).any() else math.nan
    end = len(med)
    for j in range(start, len(med)):
        if cnt[j] < min_count or not np.isfinite(med[j]) or abs(med[j] - ref) > rel * abs(ref):
            end = j
            break
    return {"reference_slope": ref, "rel": rel, "n_ref": n_ref, "start": int(start), "end": int(end),
            "d_max": float(d_mid[end - 1]) if end > start else None, "median_slope": med, "count": cnt,
            "d_mid": np.asarray(d_mid, float)}


def fit_sides(dists, br: Brackets, prof: dict, d_lo: float, d_hi: float, *, min_points: int = 4) -> np.ndarray:
    """λ (1/s) fitted to ``T0 − ln(d)/λ`` on every side (lo sides then hi sides) over ``d_lo ≤ d ≤ d_hi``, on the
    points that carry the side's label; NaN where fewer than ``min_points`` do.  Shape (2 n_borders,)."""
    d = np.asarray(dists, float)
    want, got, t = _sides(br, prof)
    sel = (d >= d_lo * (1 - 1e-12)) & (d <= d_hi * (1 + 1e-12))
    out = np.full(len(want), np.nan)
    for i in range(len(want)):
        ok = sel & (got[i] == want[i]) & np.isfinite(t[i])
        if ok.sum() >= min_points:
            out[i] = fit_settle_divergence(d[ok], t[i][ok]).lambda_per_s
    return out


def border_bootstrap(lams, n_borders: int, *, n_boot: int = 2000, seed: int = 0) -> dict:
    """Median and mean of the sides' λ (``lams``: lo sides then hi sides, NaN dropped) with bootstrap standard
    errors over borders (both sides of a border resampled together), the quartiles and the count."""
    lam = np.asarray(lams, float).reshape(2, n_borders).T  # (border, side)
    flat = lam[np.isfinite(lam)]
    out = {"n_sides": int(flat.size), "n_borders": int(n_borders)}
    if flat.size == 0:
        return out
    rng = np.random.default_rng(seed)
    meds, means = [], []
    for _ in range(n_boot):
        pick = lam[rng.integers(0, n_borders, n_borders)].ravel()
        pick = pick[np.isfinite(pick)]
        if pick.size:
            meds.append(np.median(pick))
            means.append(pick.mean())
    out.update(median=float(np.median(flat)), median_stderr=float(np.std(meds, ddof=1)) if len(meds) > 1 else None,
               mean=float(flat.mean()), mean_stderr=float(np.std(means, ddof=1)) if len(means) > 1 else None,
               q25=float(np.quantile(flat, 0.25)), q75=float(np.quantile(flat, 0.75)))
    return out


def end_flips(classify, br: Brackets) -> dict:
    """The bracket ends classified again by ``classify`` (e.g. the tolerance tightened tenfold): how many of
    the 2n verdicts differ from the bisection's, and the borders whose bracket no longer separates."""
    lab = np.asarray(classify(np.concatenate([br.p_lo, br.p_hi]))).ravel()
    n = len(br.p_lo)
    lo_changed = lab[:n] != br.label_lo
    hi_changed = lab[n:] != br.label_hi
    return {"n_ends": 2 * n, "n_changed": int(lo_changed.sum() + hi_changed.sum()),
            "fraction_changed": float((lo_changed.sum() + hi_changed.sum()) / (2 * n)) if n else None,
            "n_borders_moved": int(np.sum(lo_changed | hi_changed))}
