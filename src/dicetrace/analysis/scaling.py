"""The uncertainty exponent on its unsaturated range: local slopes of f(ε) and the crossover scale.

The fraction of uncertain pairs ``f(ε)`` (points whose outcome changes when
moved by ε) grows like ``ε**α`` at small ε and saturates at large ε, where
a random displacement lands in an unrelated cell (``f → f_sat``, the
disagreement of two independent draws, ``1 − Σ p_j²``).  A fit over all ε
mixes the two regimes.  Here:

* :func:`local_slopes`: ``d log f / d log ε`` between neighbouring ε, with
  binomial standard errors: constant on a power law, falling to 0 at
  saturation;
* :func:`unsaturated_exponent`: α fitted only where ``f ≤
  max_fraction·f_sat`` and at least ``min_changes`` pairs changed, and the
  *crossover scale* ``ε_c`` where that small-ε power law, extrapolated,
  reaches ``f_sat`` (``A ε_c**α = f_sat``).  In finite-time transient chaos a
  border is smooth below some scale, which shows as a local slope that rises
  towards 1 as ε → 0: the function reports the local slope at the smallest
  pair of scales that both carry ``min_changes`` changed pairs separately
  (``alpha_smallest``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .boundaries import fit_power_law

__all__ = ["LocalSlopes", "local_slopes", "UnsaturatedExponent", "unsaturated_exponent", "saturation_level",
           "convergence_order"]


@dataclasses.dataclass(frozen=True)
class LocalSlopes:
    """``slope[k]`` = d log f / d log ε between ``eps[k]`` and ``eps[k+1]``, at their geometric mean ``eps_mid``."""

    eps_mid: np.ndarray
    slope: np.ndarray
    stderr: np.ndarray


def local_slopes(eps, f, n) -> LocalSlopes:
    """Local slopes of ``log f`` against ``log ε`` with binomial errors (``var log f = (1 − f)/(n f)``)."""
    eps = np.asarray(eps, dtype=float)
    f = np.asarray(f, dtype=float)
    n = np.broadcast_to(np.asarray(n, dtype=float), f.shape)
    order = np.argsort(eps)
    eps, f, n = eps[order], f[order], n[order]
    with np.errstate(divide="ignore", invalid="ignore"):
        lf = np.log(f)
        var = np.where(f > 0, (1 - f) / (n * f), np.inf)
        dl = np.diff(np.log(eps))
        slope = np.diff(lf) / dl
        se = np.sqrt(var[1:] + var[:-1]) / dl
    ok = (f[1:] > 0) & (f[:-1] > 0)
    slope = np.where(ok, slope, np.nan)
    se = np.where(ok, se, np.nan)
    return LocalSlopes(np.sqrt(eps[1:] * eps[:-1]), slope, se)


def saturation_level(labels) -> float:
    """``1 − Σ p_j²``: the fraction of pairs of independent draws from ``labels`` that differ."""
    _, c = np.unique(np.asarray(labels).ravel(), return_counts=True)
    p = c / c.sum()
    return float(1.0 - np.sum(p * p))


@dataclasses.dataclass(frozen=True)
class UnsaturatedExponent:
    """α on the unsaturated range (``used``), its standard error, the crossover ``eps_c`` and the local slopes."""

    alpha: float
    alpha_stderr: float
    eps_c: float
    f_sat: float
    used: np.ndarray
    alpha_smallest: float
    alpha_smallest_stderr: float
    slopes: LocalSlopes


def unsaturated_exponent(eps, f, n, *, f_sat: float, max_fraction: float = 0.1,
                         min_changes: int = 10) -> UnsaturatedExponent:
    """α fitted on ``f ≤ max_fraction·f_sat`` with ≥ ``min_changes`` changed pairs; see the module notes.

    The fit is weighted by the binomial variance of ``log f``.  ValueError
    when fewer than two scales qualify.
    """
    eps = np.asarray(eps, dtype=float)
    f = np.asarray(f, dtype=float)
    n = np.broadcast_to(np.asarray(n, dtype=float), f.shape)
    used = (f > 0) & (f <= max_fraction * f_sat) & (f * n >= min_changes)
    if used.sum() < 2:
        raise ValueError(f"only {int(used.sum())} unsaturated scale(s) with ≥ {min_changes} changes: "
                         "measure smaller ε or more points")
    w = np.where(used, n * f / np.maximum(1 - f, 1e-300), 0.0)
    fit = fit_power_law(eps[used], f[used], weights=w[used])
    eps_c = math.exp((math.log(f_sat) - fit.intercept) / fit.slope) if fit.slope > 0 else math.nan
    sl = local_slopes(eps, f, n)
    order = np.argsort(eps)
    enough = (f * n >= min_changes)[order]
    both = enough[1:] & enough[:-1] & np.isfinite(sl.slope)  # both ends carry ≥ min_changes changed pairs
    k = int(np.flatnonzero(both)[0]) if both.any() else -1
    a_s, a_se = (float(sl.slope[k]), float(sl.stderr[k])) if k >= 0 else (math.nan, math.nan)
    se = fit.slope_stderr if math.isfinite(fit.slope_stderr) else math.nan
    return UnsaturatedExponent(float(fit.slope), float(se), float(eps_c), float(f_sat), used, a_s, a_se, sl)


def convergence_order(dts, errs) -> float:
    """Slope of log(err) against log(dt) where the error converges.

    Uses the longest run of consecutive points (from the finest step up)
    whose error decreases with dt and stays above 1e-13 cm and below 0.5 cm
    (beyond that the first impact is no longer resolved).  NaN with fewer
    than 2 such points.
    """
    d = np.asarray(dts, float)
    e = np.asarray(errs, float)
    order = np.argsort(d)
    d, e = d[order], e[order]
    good = np.isfinite(e) & (e > 1e-13) & (e < 0.5)
    idx = [i for i in range(len(d)) if good[i]]
    if len(idx) < 2:
        return float("nan")
    run = [idx[0]]
    for i in idx[1:]:
        if i == run[-1] + 1 and e[i] > e[run[-1]]:
            run.append(i)
        elif len(run) < 2:
            run = [i]
        else:
            break
    if len(run) < 2:
        return float("nan")
    slope, _ = np.polyfit(np.log(d[run]), np.log(e[run]), 1)
    return float(slope)
