"""Settle time near cell borders (writeup sections 4.1 and 5.6).

Near a border between two outcomes the die balances on an edge before it
falls one way or the other. Linearised about the balanced state the tilt
grows like ``exp(lambda t)``, so an initial condition at distance ``d`` from
the border spends a time ``~ -ln(d) / lambda`` near the edge:

    T(d) ~= T0 - ln(d) / lambda.

:func:`bisect_boundary` locates a border along a segment, :func:`settle_profile`
samples the settle time at distances from it, and :func:`fit_settle_divergence`
fits the law. :func:`edge_balance_rate` gives the rate predicted for a
uniform cube rocking on an edge (:func:`free_pivot_rate` on a frictionless floor).
:func:`fit_border` does all three for one border between two points (found by
:func:`border_pairs` on a map), :func:`divergence_summary` and
:func:`divergence_lambdas` summarise the λ of many borders, and
:func:`settle_stats` the settle times of a whole map.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np
import pandas as pd
from scipy import stats

from .boundaries import boundary_mask
from .escape import escape_rate

__all__ = [
    "BoundaryBracket",
    "SettleFit",
    "bisect_boundary",
    "fit_settle_divergence",
    "settle_profile",
    "edge_balance_rate",
    "free_pivot_rate",
    "border_pairs",
    "fit_border",
    "divergence_summary",
    "divergence_lambdas",
    "refit_halves",
    "settle_stats",
]


@dataclasses.dataclass(frozen=True)
class BoundaryBracket:
    """Two points closer than ``tol`` whose labels differ.

    Attributes
    ----------
    p_lo, p_hi : numpy.ndarray
        Bracket ends, slice units; ``p_lo`` is on the side of the segment's
        start ``p_a``.
    label_lo, label_hi
        Their labels (``label_lo`` is the label of ``p_a``).
    width : float
        ``|p_hi - p_lo|``, slice units.
    t_lo, t_hi : float
        Positions of the ends as fractions of the segment ``p_a -> p_b``.
    n_evals : int
        Calls of ``classify`` (one point each, plus the two ends).
    """

    p_lo: np.ndarray
    p_hi: np.ndarray
    label_lo: object
    label_hi: object
    width: float
    t_lo: float
    t_hi: float
    n_evals: int

    @property
    def midpoint(self) -> np.ndarray:
        return 0.5 * (self.p_lo + self.p_hi)


def _label_of(classify, p: np.ndarray):
    out = np.asarray(classify(p[None, :])).ravel()
    v = out[0]
    return v.item() if isinstance(v, np.generic) else v


def bisect_boundary(
    classify: Callable[[np.ndarray], np.ndarray],
    p_a: Sequence[float],
    p_b: Sequence[float],
    *,
    tol: float = 1e-12,
    max_iter: int = 200,
) -> BoundaryBracket:
    """Locate a label change along the segment ``p_a -> p_b`` by bisection.

    Parameters
    ----------
    classify : callable
        ``classify(points (n, d)) -> labels (n,)``, slice coordinates.
    p_a, p_b : sequence of float
        Segment ends, slice units. Their labels must differ.
    tol : float, optional
        Stop when the bracket is shorter than ``tol`` (slice units), or when
        floating point cannot split it further.
    max_iter : int, optional
        Safety cap on the number of bisections.

    Returns
    -------
    BoundaryBracket

    Raises
    ------
    ValueError
        If ``p_a`` and ``p_b`` carry the same label (there may still be an
        even number of changes between them: sample the segment first).

    Notes
    -----
    The bracket keeps the label of ``p_a`` at its low end: when the midpoint
    has that label the low end moves, otherwise the high end moves (and takes
    the midpoint's label). With several changes along the segment (or three
    labels) this converges to one of them, and the bracket reports which
    labels it separates.
    """
    a = np.asarray(p_a, dtype=float).ravel()
    b = np.asarray(p_b, dtype=float).ravel()
    if a.shape != b.shape:
        raise ValueError("p_a and p_b must have the same dimension")
    ends = np.asarray(classify(np.stack([a, b]))).ravel()
    la = ends[0].item() if isinstance(ends[0], np.generic) else ends[0]
    lb = ends[1].item() if isinstance(ends[1], np.generic) else ends[1]
    if la == lb:
        raise ValueError(
            f"both ends have label {la!r}; sample the segment to find a change first"
        )
    n_evals = 2
    t_lo, t_hi = 0.0, 1.0
    lo, hi = a.copy(), b.copy()
    d = b - a
    for _ in range(max_iter):
        if np.linalg.norm(hi - lo) < tol:
            break
        t_mid = 0.5 * (t_lo + t_hi)
        mid = a + t_mid * d
        if np.array_equal(mid, lo) or np.array_equal(mid, hi):
            break  # floating point cannot split further
        lm = _label_of(classify, mid)
        n_evals += 1
        if lm == la:
            lo, t_lo = mid, t_mid
        else:
            hi, t_hi, lb = mid, t_mid, lm
    return BoundaryBracket(
        p_lo=lo,
        p_hi=hi,
        label_lo=la,
        label_hi=lb,
        width=float(np.linalg.norm(hi - lo)),
        t_lo=t_lo,
        t_hi=t_hi,
        n_evals=n_evals,
    )


@dataclasses.dataclass(frozen=True)
class SettleFit:
    """Fit of ``T = t0_s - ln(d) / lambda_per_s``.

    Attributes
    ----------
    lambda_per_s, lambda_stderr : float
        Divergence rate (1/s when ``T`` is in s) and its standard error
        (delta method from the slope).
    t0_s, t0_stderr : float
        Settle time extrapolated to ``d = 1`` (units of ``T``).
    slope, slope_stderr : float
        ``dT / d ln d = -1 / lambda``.
    rvalue : float
    n : int
    """

    lambda_per_s: float
    lambda_stderr: float
    t0_s: float
    t0_stderr: float
    slope: float
    slope_stderr: float
    rvalue: float
    n: int


def fit_settle_divergence(d, T) -> SettleFit:
    """Fit the logarithmic divergence of settle time at a border.

    Parameters
    ----------
    d : array_like
        Distances from the border (slice units; any unit, it only shifts
        ``t0_s``). Non-positive values are dropped.
    T : array_like
        Settle times, s.

    Returns
    -------
    SettleFit
        Ordinary least squares of ``T`` on ``ln d``:
        ``T = t0 + slope ln d`` with ``lambda = -1 / slope``.
    """
    d = np.asarray(d, dtype=float).ravel()
    T = np.asarray(T, dtype=float).ravel()
    ok = (d > 0) & np.isfinite(d) & np.isfinite(T)
    d, T = d[ok], T[ok]
    if len(d) < 3:
        raise ValueError("need at least three points")
    res = stats.linregress(np.log(d), T)
    slope, se = float(res.slope), float(res.stderr)
    lam = -1.0 / slope
    return SettleFit(
        lambda_per_s=lam,
        lambda_stderr=se / slope**2,
        t0_s=float(res.intercept),
        t0_stderr=float(res.intercept_stderr),
        slope=slope,
        slope_stderr=se,
        rvalue=float(res.rvalue),
        n=len(d),
    )


def settle_profile(
    settle: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    bracket: BoundaryBracket,
    distances: Sequence[float],
    *,
    side: str = "both",
) -> pd.DataFrame:
    """Settle times at given distances from a located border point.

    Points are placed along the bracket's segment direction, at
    ``midpoint +- distance * unit`` (``+`` is the ``p_hi`` side).

    Parameters
    ----------
    settle : callable
        ``settle(points (n, d)) -> (labels (n,), t_settle_s (n,))``.
    bracket : BoundaryBracket
        From :func:`bisect_boundary`; its width should be much smaller than the
        smallest distance.
    distances : sequence of float
        Distances along the segment, slice units.
    side : {"both", "lo", "hi"}, optional

    Returns
    -------
    pandas.DataFrame
        Columns ``d`` (distance along the segment), ``side`` ("lo"/"hi"),
        ``label``, ``t_settle_s``, and the point's coordinates ``p0, p1, ...``.

    Notes
    -----
    ``d`` is measured along the segment; for a border crossed at angle
    ``phi`` the normal distance is ``d sin(phi)``, which only shifts ``T0``.
    """
    dist = np.asarray(distances, dtype=float).ravel()
    u = bracket.p_hi - bracket.p_lo
    norm = np.linalg.norm(u)
    if norm == 0:
        raise ValueError("degenerate bracket")
    u = u / norm
    sides = {"both": ("lo", "hi"), "lo": ("lo",), "hi": ("hi",)}[side]
    pts, sd, dd = [], [], []
    for s in sides:
        sign = 1.0 if s == "hi" else -1.0
        pts.append(bracket.midpoint[None, :] + sign * dist[:, None] * u[None, :])
        sd += [s] * len(dist)
        dd.append(dist)
    P = np.concatenate(pts)
    labels, t = settle(P)
    out = pd.DataFrame(
        {"d": np.concatenate(dd), "side": sd, "label": np.asarray(labels), "t_settle_s": np.asarray(t, dtype=float)}
    )
    for q in range(P.shape[1]):
        out[f"p{q}"] = P[:, q]
    return out


def edge_balance_rate(
    half_side_cm: float = 1.0, g: float = 980.0, *, inertia_factor: float = 1.0 / 6.0
) -> float:
    """Instability rate of a cube balanced on an edge, 1/s.

    Parameters
    ----------
    half_side_cm : float, optional
        Half the side ``s`` of the cube, cm (the seed die: 1 cm).
    g : float, optional
        Gravitational acceleration, cm/s^2 (default 980).
    inertia_factor : float, optional
        Moment of inertia about an axis through the centre of mass, in units
        of ``m s^2``. A uniform cube (and the seed model's
        ``I = (1/6) m s^2 E``): 1/6 (default). The eight point masses at the
        corners: 1/2.

    Returns
    -------
    float
        ``lambda = sqrt(m g r / I_edge)``; for the uniform cube
        ``sqrt(3 g / (2 sqrt(2) s))`` = 22.8 1/s for ``s = 2`` cm.

    Notes
    -----
    The die pivots about the edge in contact with the ground. Its centre of
    mass is at ``r = s / sqrt(2)`` from the edge (half the diagonal of a
    face). By the parallel-axis theorem
    ``I_edge = I_cm + m r^2 = (1/6 + 1/2) m s^2 = (2/3) m s^2``.
    At tilt ``phi`` from the balanced (centre of mass above the edge)
    position gravity exerts the torque ``m g r sin(phi)``, so
    ``I_edge phi'' = m g r sin(phi) ~ m g r phi`` and
    ``phi ~ exp(lambda t)`` with
    ``lambda^2 = m g r / I_edge = g (s / sqrt 2) / ((2/3) s^2)
    = 3 g / (2 sqrt(2) s)``. It ignores the ground's compliance and friction
    (the pivot is assumed fixed), so it is the ideal rigid-body value.
    """
    s = 2.0 * float(half_side_cm)
    r = s / math.sqrt(2.0)
    i_edge = (float(inertia_factor) + 0.5) * s * s  # per unit mass
    return math.sqrt(float(g) * r / i_edge)


def free_pivot_rate(half_side_cm: float = 1.0, g: float = 980.0) -> float:
    """Edge-balance rate with a frictionless floor: only the CM height couples, I_cm = m s²/6.

    At small tilt φ the CM moves vertically only (no horizontal force), so the kinetic energy is
    ½ I_cm φ'² (+ O(φ²)), and λ² = m g r / I_cm with r = s/√2.
    """
    s = 2.0 * half_side_cm
    return math.sqrt(g * (s / math.sqrt(2.0)) / (s * s / 6.0))


def border_pairs(s, n_borders: int, rng: np.random.Generator) -> list:
    """Up to ``n_borders`` random face-neighbour pairs of the map ``s`` (a WindowSample) whose outcomes differ,
    both settled: ((x, y), (x', y')) each."""
    g = s.labels
    ax, ay = s.axes
    pairs = []
    for off in ((1, 0), (0, 1)):
        a = g[: g.shape[0] - off[0], : g.shape[1] - off[1]]
        b = g[off[0]:, off[1]:]
        ii, jj = np.nonzero((a != b) & (a > 0) & (b > 0))
        for i, j in zip(ii, jj):
            pairs.append(((ax[i], ay[j]), (ax[i + off[0]], ay[j + off[1]])))
    pick = rng.choice(len(pairs), size=min(n_borders, len(pairs)), replace=False)
    return [pairs[q] for q in pick]


def fit_border(classify, settle, pa, pb, dists) -> tuple[dict, object]:
    """Bisect one border between ``pa`` and ``pb`` (``classify``), sample the settle time at distances ``dists`` on
    both sides (``settle``) and fit T ≈ T0 − ln(d)/λ on each side with six points or more: (numbers, the profile)."""
    br = bisect_boundary(classify, pa, pb, tol=1e-12)
    prof = settle_profile(settle, br, dists)
    out = {"p_lo": br.p_lo, "p_hi": br.p_hi, "width": br.width, "label_lo": br.label_lo, "label_hi": br.label_hi,
           "n_evals": br.n_evals}
    for side, lab in (("lo", br.label_lo), ("hi", br.label_hi)):
        p = prof[prof.side == side]
        ok = (p.label == lab).to_numpy()
        out[f"{side}_n_ok"] = int(ok.sum())
        if ok.sum() >= 6:
            f = fit_settle_divergence(p.d[ok], p.t_settle_s[ok])
            out[side] = {"lambda": f.lambda_per_s, "lambda_stderr": f.lambda_stderr, "t0": f.t0_s, "r": f.rvalue}
        else:
            out[side] = None
    out["t_range_s"] = [float(prof.t_settle_s.min()), float(prof.t_settle_s.max())]
    return out, prof


def divergence_summary(fits: list[dict]) -> dict:
    """λ over the sides of :func:`fit_border` results: median with quartiles and a bootstrap stderr (seeded), and the
    mean ± stderr, min and max of the clean fits (r < −0.995); ``all`` and ``r`` hold every side's λ and r."""
    lam = np.array([f[side]["lambda"] for f in fits for side in ("lo", "hi") if f.get(side)])
    r = np.array([f[side]["r"] for f in fits for side in ("lo", "hi") if f.get(side)])
    clean = lam[r < -0.995]
    out = {"n_fits": int(len(lam)), "n_clean": int(len(clean))}
    if len(lam):
        out.update(median=float(np.median(lam)), q25=float(np.quantile(lam, 0.25)),
                   q75=float(np.quantile(lam, 0.75)))
        # bootstrap stderr of the median
        rng = np.random.default_rng(0)
        bs = [np.median(lam[rng.integers(0, len(lam), len(lam))]) for _ in range(500)]
        out["median_stderr"] = float(np.std(bs, ddof=1)) if len(lam) > 1 else None
    if len(clean):
        out.update(clean_mean=float(clean.mean()),
                   clean_stderr=float(clean.std(ddof=1) / math.sqrt(len(clean))) if len(clean) > 1 else None,
                   clean_min=float(clean.min()), clean_max=float(clean.max()))
    out["all"] = lam
    out["r"] = r
    return out


def settle_stats(s) -> dict:
    """Settle-time statistics of a map ``s`` (``labels``, ``t_settle_s``): quantiles, border against interior, and
    the escape rate κ."""
    t, g = s.t_settle_s, s.labels
    ok = g > 0
    tt = t[ok]
    border = boundary_mask(g) & ok
    inner = ~boundary_mask(g) & ok
    out = {
        "n_settled": int(ok.sum()), "n_unsettled": int((g == -1).sum()),
        "mean": float(tt.mean()), "mean_stderr": float(tt.std(ddof=1) / math.sqrt(len(tt))) if len(tt) > 1 else None,
        "median": float(np.median(tt)), "q90": float(np.quantile(tt, 0.9)), "max": float(tt.max()),
        "border_mean": float(t[border].mean()) if border.any() else None,
        "interior_mean": float(t[inner].mean()) if inner.any() else None,
    }
    try:
        k = escape_rate(tt, min_tail=10, censored_at=float(np.max(t)) if (g == -1).any() else None)
        out.update(kappa=k.kappa, kappa_stderr=k.stderr, kappa_t0=k.t0, kappa_t1=k.t1)
    except ValueError as e:
        out.update(kappa=None, kappa_stderr=None, kappa_error=str(e))
    return out


def divergence_lambdas(fits: list[dict]) -> dict:
    """:func:`divergence_summary` of :func:`fit_border` results with every side's λ as ``lambdas`` (no ``all``,
    ``r``), the number of borders and, with any λ, their mean ± stderr."""
    out = divergence_summary(fits)
    lam = np.asarray(out.pop("all"), dtype=float)
    out.pop("r")
    out["n_borders"] = len(fits)
    out["lambdas"] = lam
    if len(lam):
        out["mean"] = float(lam.mean())
        out["mean_stderr"] = float(lam.std(ddof=1) / math.sqrt(len(lam))) if len(lam) > 1 else None
    return out


def refit_halves(prof, lab_by_side) -> tuple[list, list]:
    """λ refitted on the near and the far half (in log distance) of each side of a :func:`settle_profile`, sides
    whose points carry their label in ``lab_by_side``; halves with four points or more: (near λs, far λs)."""
    near, far = [], []
    split = math.sqrt(prof.d.min() * prof.d.max())
    for side, lab in lab_by_side.items():
        p = prof[(prof.side == side) & (prof.label == lab)]
        for sel, acc in ((p.d <= split, near), (p.d > split, far)):
            q = p[sel]
            if len(q) >= 4:
                acc.append(fit_settle_divergence(q.d, q.t_settle_s).lambda_per_s)
    return near, far
