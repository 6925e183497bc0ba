"""How a fitted or located number moves with the choice that produced it: its statistical error beside its systematic.

A rate fitted over one range of distances, times or tilts, or a point located
by one integrator, carries two errors: the statistical one of that fit, and
how far the number moves when the choice is made otherwise.  The report
quotes both, side by side, and says so where the second exceeds the first.

* :func:`range_scan` fits over nested ranges (shortest first, each one
  holding the one before) and quotes the fit of a reference range, by default
  the shortest (the limit as the range shrinks).  Its *range systematic* is
  one-sided: how far above (``syst_hi``) and how far below (``syst_lo``) the
  quoted value the other ranges go, and the straight-line extrapolation of
  the values to zero width, when asked for and where it departs from the
  quoted value by more than its own error.  A trend with the range then shows
  as a systematic on one side only.
* :func:`relocate` compares a point located by several independent
  integrators (or settings): the largest distance of any from the reference's
  point (``spread``) against the reference's own bracket (``box``).  A
  location is reproducible only to the larger of the two; an integrator that
  did not find the point makes the spread infinite.
* :func:`common_scale`: the smallest of a descending series of scales down to
  which every integrator sees what the reference sees (the faces on a circle
  about a located point, say), from the largest scale on.
* :func:`group_spread`: a number measured in several groups (windows of a
  map, say): the spread between the groups, which a pooled count's error
  leaves out.
* :func:`stat_syst` and :func:`syst_note` write the two errors and the verdict
  note; :func:`one_sided_z` compares a value with a target using the
  systematic of the side the target lies on.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

__all__ = ["RangeScan", "range_scan", "Relocation", "relocate", "common_scale", "group_spread", "stat_syst",
           "syst_note", "one_sided_z"]


@dataclasses.dataclass(frozen=True)
class RangeScan:
    """A number fitted over nested ranges (:func:`range_scan`).

    ``values``/``stderrs``: the fit of every range (NaN where it failed);
    ``widths``: each range's width (decades for ranges of positive numbers,
    else ``hi − lo``, unless given).  ``value``/``stat``: the quoted range's
    fit and its statistical error; ``syst_lo``/``syst_hi`` (≥ 0): how far below
    and above ``value`` the ranges that enter the systematic (and the
    extrapolation) go; ``extrapolated``: the weighted straight line through
    those ranges' values against their widths, at width 0, and ``trend`` its
    slope per unit of width (NaN without it).
    """

    ranges: tuple[tuple[float, float], ...]
    widths: np.ndarray
    values: np.ndarray
    stderrs: np.ndarray
    reference: int
    value: float
    stat: float
    syst_lo: float
    syst_hi: float
    n_syst: int
    extrapolated: float
    extrapolated_stderr: float
    trend: float

    @property
    def syst(self) -> float:
        """The larger side of the systematic."""
        return max(self.syst_lo, self.syst_hi)

    @property
    def syst_dominates(self) -> bool:
        """Whether the systematic exceeds the statistical error (a NaN statistical error counts as exceeded)."""
        return bool(self.syst > self.stat) if math.isfinite(self.stat) else self.syst > 0

    def as_dict(self) -> dict:
        """JSON-able: every field, with the ranges as lists and NaN as None."""

        def num(v):
            v = float(v)
            return v if math.isfinite(v) else None

        return {"ranges": [[float(a), float(b)] for a, b in self.ranges], "widths": [num(v) for v in self.widths],
                "values": [num(v) for v in self.values], "stderrs": [num(v) for v in self.stderrs],
                "reference": self.reference, "value": num(self.value), "stat": num(self.stat),
                "syst_lo": num(self.syst_lo), "syst_hi": num(self.syst_hi), "syst": num(self.syst),
                "syst_dominates": self.syst_dominates, "n_syst": self.n_syst,
                "extrapolated": num(self.extrapolated), "extrapolated_stderr": num(self.extrapolated_stderr),
                "trend": num(self.trend)}


def _widths(ranges) -> np.ndarray:
    r = np.asarray(ranges, dtype=float)
    if np.all(r > 0):
        return np.log10(r[:, 1] / r[:, 0])
    return r[:, 1] - r[:, 0]


def _line_at_zero(w: np.ndarray, v: np.ndarray, e: np.ndarray) -> tuple[float, float, float]:
    """Weighted least squares of ``v`` against ``w`` (weights 1/e², equal weights where an error is missing or 0):
    its value at w = 0, that value's standard error from the fit's covariance, and its slope (NaN with fewer than
    three points)."""
    if len(w) < 3 or np.ptp(w) == 0:
        return math.nan, math.nan, math.nan
    good = np.isfinite(e) & (e > 1e-12 * np.maximum(np.abs(v), 1e-300))  # an error of rounding size is no weight
    wt = 1.0 / e**2 if good.all() else np.ones_like(v)
    A = np.column_stack([np.ones_like(w), w])
    try:
        cov = np.linalg.inv(A.T @ (A * wt[:, None]))
    except np.linalg.LinAlgError:
        return math.nan, math.nan, math.nan
    coef = cov @ (A.T @ (wt * v))
    resid = v - A @ coef
    dof = len(w) - 2
    scale = float(resid @ (wt * resid)) / dof if dof > 0 else 1.0
    if not good.all():  # unweighted: the covariance is the residuals' only
        return float(coef[0]), float(math.sqrt(cov[0, 0] * scale)), float(coef[1])
    return float(coef[0]), float(math.sqrt(cov[0, 0] * max(scale, 1.0))), float(coef[1])


def range_scan(fit: Callable[[float, float], object], ranges: Sequence[tuple[float, float]], *,
               widths: Sequence[float] | None = None, reference: int = 0, syst_over: int | None = None,
               extrapolate: bool = False) -> RangeScan:
    """``fit(lo, hi)`` over each of the nested ``ranges`` (shortest first), the quoted value and its range systematic.

    ``fit`` returns a value or ``(value, stderr)``; a ValueError or a
    non-finite value marks that range as failed (NaN).  ``reference``: the
    index of the range quoted (0, the shortest: the limit as the range
    shrinks).  ``syst_over``: how many ranges, from the shortest, enter the
    systematic (all by default); the others are fitted and kept (a curve to
    show) but do not move it.  ``extrapolate``: the straight-line
    extrapolation of those ranges' values to zero width enters the systematic
    too where it departs from the quoted value by more than its own standard
    error (a trend with the width, not the noise of the fits).  ValueError
    when the ranges are not nested or the reference range's fit failed.
    """
    rs = tuple((float(a), float(b)) for a, b in ranges)
    if not rs:
        raise ValueError("no ranges")
    for (a0, b0), (a1, b1) in zip(rs, rs[1:]):
        if a1 > a0 or b1 < b0:
            raise ValueError(f"ranges must be nested, shortest first: {(a0, b0)} then {(a1, b1)}")
    vals, errs = [], []
    for lo, hi in rs:
        try:
            out = fit(lo, hi)
        except ValueError:
            out = math.nan
        v, e = (out if isinstance(out, tuple) else (out, math.nan))
        vals.append(math.nan if v is None else float(v))
        errs.append(math.nan if e is None else float(e))
    values, stderrs = np.array(vals), np.array(errs)
    w = np.asarray(widths, dtype=float) if widths is not None else _widths(rs)
    ref = int(reference)
    value, stat = float(values[ref]), float(stderrs[ref])
    if not math.isfinite(value):
        raise ValueError(f"the reference range {rs[ref]} has no fit")
    n = len(rs) if syst_over is None else max(1, min(int(syst_over), len(rs)))
    used = np.isfinite(values[:n])
    others = list(values[:n][used])
    ext, ext_se, trend = math.nan, math.nan, math.nan
    if extrapolate:
        ext, ext_se, trend = _line_at_zero(w[:n][used], values[:n][used], stderrs[:n][used])
        if math.isfinite(ext) and not abs(ext - value) <= ext_se:  # a trend, not the fits' noise
            others.append(ext)
    others = np.array(others)
    lo = float(max(0.0, value - others.min())) if others.size else 0.0
    hi = float(max(0.0, others.max() - value)) if others.size else 0.0
    return RangeScan(rs, w, values, stderrs, ref, value, stat, lo, hi, int(used.sum()), ext, ext_se, trend)


@dataclasses.dataclass(frozen=True)
class Relocation:
    """A point located by several integrators (:func:`relocate`).

    ``points`` (n, dim; NaN rows: not found), ``found``, ``distances`` from
    the reference's point (inf: not found), ``spread`` (the largest of them),
    ``box`` (the reference's own bracket) and ``reproducible`` (the larger of
    ``box`` and ``spread``: the precision to which the location is the same
    for every integrator).
    """

    names: tuple[str, ...]
    reference: str
    points: np.ndarray
    found: np.ndarray
    distances: np.ndarray
    box: float
    spread: float
    reproducible: float

    def as_dict(self) -> dict:
        return {"names": list(self.names), "reference": self.reference,
                "points": [[float(v) for v in p] if f else None for p, f in zip(self.points, self.found)],
                "found": [bool(f) for f in self.found],
                "distances": [float(d) if math.isfinite(d) else None for d in self.distances],
                "box": float(self.box), "spread": float(self.spread) if math.isfinite(self.spread) else None,
                "reproducible": float(self.reproducible) if math.isfinite(self.reproducible) else None}


def relocate(points: Mapping[str, Sequence[float] | None], *, reference: str, box: float) -> Relocation:
    """How far the point each integrator located (``points``: name -> point, or None where it found none) lies from
    the ``reference`` integrator's, against that one's bracket ``box``.  ValueError when the reference found
    none."""
    names = tuple(points)
    if reference not in points or points[reference] is None:
        raise ValueError(f"the reference {reference!r} located no point")
    dim = len(points[reference])
    P = np.array([np.full(dim, np.nan) if points[n] is None else np.asarray(points[n], float) for n in names])
    found = np.all(np.isfinite(P), axis=1)
    r = P[names.index(reference)]
    d = np.where(found, np.linalg.norm(P - r, axis=1), np.inf)
    spread = float(d.max())
    return Relocation(names, reference, P, found, d, float(box), spread, max(float(box), spread))


def common_scale(scales: Sequence[float], seen: Mapping[str, Sequence], *, reference: str,
                 require=None) -> float | None:
    """The smallest of the descending ``scales`` down to which every integrator's observation (``seen``: name ->
    one observation per scale, compared with ``==``) is the reference's at that scale and every larger one; None
    when they differ at the largest.  ``require``: every observation must also equal it (say, True for "three
    sectors of the point's faces"), not merely agree with the reference's."""
    s = [float(v) for v in scales]
    if any(b >= a for a, b in zip(s, s[1:])):
        raise ValueError("scales must be strictly descending")
    ref = list(seen[reference])
    best = None
    for i, sc in enumerate(s):
        if all(list(obs)[i] == ref[i] for obs in seen.values()) and (require is None or ref[i] == require):
            best = sc
        else:
            break
    return best


def group_spread(values: Sequence[float]) -> dict:
    """The groups' values (NaN dropped): their mean, the standard error of that mean from their scatter (the spread
    between groups: sample standard deviation over √groups), the standard deviation, and the range; NaN where fewer
    than two groups have a value."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    n = int(v.size)
    if n == 0:
        return {"n": 0, "mean": math.nan, "spread": math.nan, "std": math.nan, "min": math.nan, "max": math.nan}
    sd = float(v.std(ddof=1)) if n > 1 else math.nan
    return {"n": n, "mean": float(v.mean()), "spread": sd / math.sqrt(n) if n > 1 else math.nan, "std": sd,
            "min": float(v.min()), "max": float(v.max())}


def stat_syst(value: float, stat: float, syst_lo: float, syst_hi: float, spec: str = ".2f",
              what: str = "range") -> str:
    """``value ± stat (stat) +hi −lo (what)``, or ``± s (what)`` when the two sides are equal; a missing statistical
    error prints as a dash."""
    v = format(value, spec)
    s = format(stat, spec) if stat is not None and math.isfinite(stat) else "–"
    if format(syst_lo, spec) == format(syst_hi, spec):
        return f"{v} ± {s} (stat) ± {format(syst_hi, spec)} ({what})"
    return f"{v} ± {s} (stat) +{format(syst_hi, spec)} −{format(syst_lo, spec)} ({what})"


def syst_note(stat: float, syst: float, what: str = "fit-range", spec: str = ".2f") -> str:
    """A verdict's note when the systematic exceeds the statistical error ('' otherwise)."""
    if stat is not None and math.isfinite(stat) and syst <= stat:
        return ""
    s = format(stat, spec) if stat is not None and math.isfinite(stat) else "none"
    return (f"its {what} systematic ({format(syst, spec)}) exceeds its statistical error ({s}), so the "
            f"systematic, not the statistics, limits it")


def one_sided_z(value: float, stat: float, syst_lo: float, syst_hi: float, target: float,
                target_err: float = 0.0) -> float:
    """(value − target) over the statistical error, the systematic of the side the target lies on and the target's
    error, in quadrature (NaN when all three are 0)."""
    side = syst_lo if target < value else syst_hi
    err = math.sqrt((stat if stat is not None and math.isfinite(stat) else 0.0) ** 2 + side**2 + target_err**2)
    return (value - target) / err if err > 0 else math.nan
