"""How fair is a die: baseline models of the face probabilities of a box, and the statistics to hold a model to data.

**Models.**  Each is a closed formula of the die's shape, with its derivation
in its docstring:

- :func:`solid_angle_p` / :func:`solid_angle_faces`: a face's probability is
  the solid angle it subtends from the centre of mass, over 4π (the "simple
  explanation" the Gazette note 97.16 cites as its reference [2]).
- :func:`edge_tip_p`: the first step of the Gazette note's edge-landing model
  (the only step whose text could be read; see its docstring).
- :func:`gibbs_p` / :func:`gibbs_faces`: a Gibbs (Boltzmann) distribution over
  the faces with the potential energy of the centre of mass resting on each
  face and a "temperature" fitted to the conditions (Riemer, Stoyan &
  Obreschkow, Metrika 2013, arXiv:1302.3925; only their abstract could be
  read, so the form implemented is the one stated there and in issue 43, not
  checked against their equations).
- :func:`pender_uhrin_ratio` / :func:`pender_uhrin_p`: Pender & Uhrin's closed
  formula for a two-dimensional die (a long bar), arXiv:1407.6307.

The square-cuboid functions take the aspect ratio ``x/y`` of
:data:`dicetrace.analysis.dice_data.GAZETTE_97_16` (two y×y square faces, four
x×y faces) and return ``p``, the probability that a square face ends up (by
symmetry, also the probability that the die rests on one).  The box functions
take three half-extents along the body axes and an optional centre-of-mass
offset, and return the probability of each face ending **up**, in the face
numbering of docs/model.md §3 (:data:`FACE_AXES`): a die that rests on face
``j`` shows the opposite face ``7 - j``.

**Statistics.**  :func:`compare` holds a model to measured shares (χ² and
per-point z with the binomial error of the data and, for a Monte-Carlo model,
its own), :func:`fit_one_parameter` fits one parameter on named points and
keeps the other points as predictions, and :func:`throws_to_detect` says how
many throws a player needs to detect a given bias at a given level and power.
Wilson intervals of face counts are :func:`dicetrace.analysis.grouping.wilson_interval`
(equal to scipy's ``binomtest(k, n).proportion_ci(method="wilson")`` to 1e-12,
and vectorised) and :func:`~dicetrace.analysis.grouping.basins_fractions_table`
for a table of them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from dicetrace import body
from scipy import optimize, special, stats

from .dice_data import GAZETTE_97_16, MeasuredCuboids

__all__ = [
    "FACE_AXES", "Comparison", "DetectionPlan", "OneParameterFit", "compare", "edge_tip_p", "edge_tip_square_share",
    "face_counts",
    "fit_one_parameter", "gibbs_faces", "gibbs_p", "pender_uhrin_p", "pender_uhrin_ratio", "solid_angle_faces",
    "solid_angle_p", "throws_to_detect",
]

#: Face f (1..6) of docs/model.md §3 lies on the side ``sign`` of body axis ``axis``: FACE_AXES[f - 1] = (axis, sign).
FACE_AXES = body.FACE_AXES


def _aspect(aspect) -> np.ndarray:
    r = np.asarray(aspect, dtype=float)
    if not np.all(np.isfinite(r)) or np.any(r <= 0):
        raise ValueError(f"aspect ratio x/y must be finite and > 0, got {aspect!r}")
    return r


def _out(x: np.ndarray):
    return float(x) if x.ndim == 0 else x


def _box(half_extents, com) -> tuple[np.ndarray, np.ndarray]:
    h = np.asarray(half_extents, dtype=float)
    c = np.zeros(3) if com is None else np.asarray(com, dtype=float)
    if h.shape != (3,) or not np.all(np.isfinite(h)) or np.any(h <= 0):
        raise ValueError(f"half_extents must be three finite numbers > 0, got {half_extents!r}")
    if c.shape != (3,) or not np.all(np.isfinite(c)) or np.any(np.abs(c) >= h):
        raise ValueError(f"the centre of mass {com!r} must be three finite numbers strictly inside the box ±{h.tolist()}")
    return h, c


def _face_distances(h: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance from the centre of mass to the plane of each face 1..6 (the CM's height resting on that face)."""
    return np.array([h[axis] - sign * c[axis] for axis, sign in FACE_AXES])


def _up(p_rest: np.ndarray) -> np.ndarray:
    """Probabilities of each face up from those of resting on each face (face j down shows 7 - j)."""
    return p_rest[::-1].copy()


# -- solid angle --------------------------------------------------------------------------------------


def _corner_solid_angle(a, b, h):
    """Signed solid angle of the rectangle [0, a] × [0, b] seen from height h above its corner (0, 0).

    Ω = arctan(a·b / (h·√(a² + b² + h²))) (odd in a and in b), the classic
    result of integrating h/ρ³ over the rectangle.
    """
    return np.arctan(a * b / (h * np.sqrt(a * a + b * b + h * h)))


def solid_angle_faces(half_extents, com=None) -> np.ndarray:
    """Solid-angle model of a box: P(face f up) = Ω(face opposite f) / 4π, Ω seen from the centre of mass.

    Derivation: the model supposes that the die comes to rest on the face
    through which the downward vertical leaves the body from its centre of
    mass, with every direction equally likely (a die "put down" in a uniformly
    random orientation with no bounce).  The share of directions that leave
    through face j is its solid angle over 4π.  A face at distance h from the
    point, spanning [u1, u2] × [v1, v2] about the foot of the perpendicular,
    subtends Ω = F(u2, v2) − F(u1, v2) − F(u2, v1) + F(u1, v1) with
    F(a, b) = arctan(a·b / (h·√(a² + b² + h²))); the six solid angles add up to
    4π for any point inside the box (Gauss), so the probabilities sum to 1.

    Parameters
    ----------
    half_extents : three floats > 0
        Half-extents of the box along the body axes x, y, z.
    com : three floats, optional
        Centre of mass relative to the box's centre (a loaded die), strictly inside.

    Returns
    -------
    numpy.ndarray (6,)
        P(face f up) for f = 1..6 (:data:`FACE_AXES`).
    """
    h, c = _box(half_extents, com)
    omega = np.empty(6)
    for j, (axis, sign) in enumerate(FACE_AXES):
        u, v = [ax for ax in range(3) if ax != axis]
        dist = h[axis] - sign * c[axis]
        u1, u2 = -h[u] - c[u], h[u] - c[u]
        v1, v2 = -h[v] - c[v], h[v] - c[v]
        omega[j] = (_corner_solid_angle(u2, v2, dist) - _corner_solid_angle(u1, v2, dist)
                    - _corner_solid_angle(u2, v1, dist) + _corner_solid_angle(u1, v1, dist))
    return _up(omega / (4.0 * math.pi))


def solid_angle_p(aspect):
    """Solid-angle model of a square cuboid: p(x/y) = (2/π)·arcsin(1 / (1 + (x/y)²)).

    A y×y square face seen from the centre, at distance x/2, subtends
    Ω = 4·arctan((y/2)² / ((x/2)·√((y/2)² + (y/2)² + (x/2)²))) = 4·arcsin(y² / (x² + y²))
    (the corner formula of :func:`solid_angle_faces` on its four quarters,
    and arctan(s/√(1 − s²)) = arcsin s).  The two square faces together
    cover 2Ω of 4π: p = 2Ω/4π.  Limits: p(1) = 1/3 (a cube), p → 1 as x/y → 0
    (a flat tile lands flat; 1 − p ≈ (2√2/π)·x/y), p ≈ (2/π)·(y/x)² → 0 as
    x/y → ∞ (a long bar).
    """
    r = _aspect(aspect)
    # arcsin(1/(1 + r²)) = arctan(1/(r·√(2 + r²))): the same angle, without the loss near r → 0
    return _out(2.0 / math.pi * np.arctan2(1.0, r * np.sqrt(2.0 + r * r)))


# -- the Gazette note's edge landing ------------------------------------------------------------------


def edge_tip_square_share(aspect):
    """Step 1 of the Gazette note's edge-landing model: q(x/y) = (2/π)·arctan(y/x).

    The Mathematical Gazette 97 (2013), note 97.16, builds its model "in
    three steps"; only the first could be read: the die lands vertically,
    without rotation, on one of its eight edges of length y (each joins a
    square face and an x×y face), its bottom square face at angle θ to the
    floor (the note's Figure 2), and then falls over onto that square face or
    onto the x×y face, whichever side of the edge its centre of mass is on.

    Derivation (ours, from that text): in the section across the edge the die
    is an x×y rectangle (y along the square face, x along the other face); the
    centre of mass sits at angle φ = arctan(x/y) from the square face, so at
    angle θ + φ from the floor.  It is beyond the vertical through the edge on
    the square face's side, and the die falls onto the square face, when
    θ + φ < π/2.  With θ uniform on [0, π/2] (an assumption: the distribution
    of θ is not in the part of the note that could be read) the share is
    q = (π/2 − arctan(x/y)) / (π/2) = (2/π)·arctan(y/x): 1/2 for a cube, → 1 as
    x/y → 0 and → 0 as x/y → ∞.

    This is *not* the note's final model: its steps 2 and 3 could not be read
    and are not implemented.  See :func:`edge_tip_p` for a full p built on it.
    """
    r = _aspect(aspect)
    return _out(2.0 / math.pi * np.arctan(1.0 / r))


def edge_tip_p(aspect, *, y_edge_share: float = 2.0 / 3.0):
    """p(x/y) when the die first lands on an edge and tips over it once: ``y_edge_share``·q(x/y).

    A die landing on one of the four x-edges (each between two x×y faces)
    always ends on an x×y face; on one of the eight y-edges it ends on a
    square face with the share q of :func:`edge_tip_square_share`.  With every
    edge equally likely (``y_edge_share = 8/12``, an assumption of ours, not
    of the note) p(1) = 1/3, as a cube needs.  Limits: p → y_edge_share as
    x/y → 0 and p → 0 as x/y → ∞.  Not the Gazette note's final model (see
    :func:`edge_tip_square_share`).
    """
    if not (0.0 <= y_edge_share <= 1.0):
        raise ValueError(f"y_edge_share must be in [0, 1], got {y_edge_share!r}")
    return _out(y_edge_share * np.asarray(edge_tip_square_share(aspect)))


# -- Gibbs ----------------------------------------------------------------------------------------------


def gibbs_faces(half_extents, temperature: float, com=None) -> np.ndarray:
    """Gibbs model of a box: P(rest on face j) ∝ exp(−h_j / λ), h_j the height of the centre of mass resting on j.

    Derivation: the die's potential energy resting on face j is M·g·h_j with
    h_j the distance from its centre of mass to the plane of face j.  A Gibbs
    (Boltzmann) distribution over the six resting states with a "temperature"
    T gives P_j ∝ exp(−M·g·h_j / T) = exp(−h_j / λ), where λ = T/(M·g) is a
    length that condenses the physical conditions (throw, surface) into one
    parameter to be fitted (Riemer, Stoyan & Obreschkow, Metrika 2013,
    arXiv:1302.3925, as their abstract and issue 43 describe the model; their
    equations could not be read).  λ → ∞ gives every face 1/6, λ → 0 only the
    lowest resting states; a cube with its centre of mass at its centre gives
    1/6 at every λ.

    Parameters
    ----------
    half_extents : three floats > 0
        Half-extents along the body axes x, y, z.
    temperature : float > 0
        λ, in the units of ``half_extents``.
    com : three floats, optional
        Centre of mass relative to the box's centre.

    Returns
    -------
    numpy.ndarray (6,)
        P(face f up) for f = 1..6 (:data:`FACE_AXES`).
    """
    h, c = _box(half_extents, com)
    lam = float(temperature)
    if not (math.isfinite(lam) and lam > 0):
        raise ValueError(f"temperature must be a finite number > 0, got {temperature!r}")
    dist = _face_distances(h, c)
    w = np.exp(-(dist - dist.min()) / lam)
    return _up(w / w.sum())


def gibbs_p(aspect, temperature):
    """Gibbs model of a square cuboid: p(x/y) = 1 / (1 + 2·exp((x/y − 1) / (2t))), t = λ/y.

    From :func:`gibbs_faces`: resting on a square face the centre of mass is at
    x/2, on an x×y face at y/2, so p = 2e^{−x/2λ} / (2e^{−x/2λ} + 4e^{−y/2λ}).
    p(1) = 1/3 at every t; p → 1/(1 + 2e^{−1/2t}) (not 1) as x/y → 0, and
    p → 0 as x/y → ∞; t → ∞ gives p = 1/3 at every shape.
    """
    r = _aspect(aspect)
    t = np.asarray(temperature, dtype=float)
    if not np.all(np.isfinite(t)) or np.any(t <= 0):
        raise ValueError(f"temperature must be finite and > 0, got {temperature!r}")
    return _out(special.expit(-(r - 1.0) / (2.0 * t) - math.log(2.0)))  # 1/(1 + 2e^u) without overflow


# -- Pender & Uhrin: the 2-D die --------------------------------------------------------------------------


def pender_uhrin_ratio(k, l):
    """Pender & Uhrin's ratio for a 2-D die (a k×l rectangle): P(rest on a side of length l) / P(rest on a side of length k).

    The formula of arXiv:1407.6307 (abstract):

        R = (√(k² + l²) − k) / (√(k² + l²) − l) · arctan(l/k) / arctan(k/l).

    Reading of its terms (ours): resting on a side of length l the centre of
    mass is at height k/2 and must rise by (√(k² + l²) − k)/2 to tip over a
    corner (the energy barrier), through a tilt of arctan(l/k) (the width of
    the state's basin); the ratio is that of the products barrier·width of the
    two states, so R < 1 when k > l (the bar prefers its wide side).  R(k, k) = 1,
    R(l, k) = 1/R(k, l), and R ≈ (l/k)³/π as k/l → ∞.  The authors note that
    the formula assumes a bouncy or "grippy" surface and that their measured
    ratios were somewhat closer to 1.
    """
    k = np.asarray(k, dtype=float)
    l = np.asarray(l, dtype=float)
    if not (np.all(np.isfinite(k)) and np.all(np.isfinite(l)) and np.all(k > 0) and np.all(l > 0)):
        raise ValueError(f"side lengths must be finite and > 0, got k={k!r}, l={l!r}")
    d = np.hypot(k, l)
    return _out((d - k) / (d - l) * np.arctan(l / k) / np.arctan(k / l))


def pender_uhrin_p(k, l):
    """Share of throws of a long bar of section k×l that end on one of its two sides of length l: R/(1 + R)."""
    r = np.asarray(pender_uhrin_ratio(k, l))
    return _out(r / (1.0 + r))


# -- a model against data ---------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Comparison:
    """A model's p against measured shares, point by point.

    Attributes
    ----------
    aspect, p_obs, n, p_model : numpy.ndarray
        The points compared (those of ``points``), their measured shares,
        throws and the model's p.
    sigma : numpy.ndarray
        Standard error of ``p_obs − p_model``: √(p(1 − p)/n) at the model's p;
        for a Monte-Carlo model √(p̄(1 − p̄)(1/n + 1/n_model)) at the pooled share p̄.
    z : numpy.ndarray
        (p_obs − p_model)/sigma; ±inf where sigma is 0 and the two differ.
    chi2 : float
        Σ z².
    dof : int
        Points compared minus the parameters fitted on them.
    p_value : float
        P(χ²_dof ≥ chi2).
    """

    aspect: np.ndarray
    p_obs: np.ndarray
    n: np.ndarray
    p_model: np.ndarray
    sigma: np.ndarray
    z: np.ndarray
    chi2: float
    dof: int
    p_value: float

    @property
    def chi2_per_point(self) -> float:
        return self.chi2 / len(self.z)


def _point_index(data: MeasuredCuboids, points) -> np.ndarray:
    if points is None:
        return np.arange(len(data))
    idx = []
    for a in points:
        hit = np.flatnonzero(np.abs(data.aspect - float(a)) < 1e-9)
        if hit.size != 1:
            raise ValueError(f"no measured point at x/y = {a!r} (the points are {data.aspect.tolist()})")
        idx.append(int(hit[0]))
    if len(set(idx)) != len(idx) or not idx:
        raise ValueError(f"points must name distinct measured aspect ratios, got {list(points)!r}")
    return np.array(sorted(idx))


def compare(p_model, data: MeasuredCuboids = GAZETTE_97_16, *, model_n=None, points=None, n_fitted: int = 0,
            dispersion: float = 1.0) -> Comparison:
    """χ² and per-point z of a model against measured square-face shares.

    Each measured share is binomial: its standard error is √(p(1 − p)/N),
    taken at the model's p (Pearson's χ² for two categories, finite where a
    measured share is 0 or 1).  A Monte-Carlo model (``model_n`` given) is a
    second sample: the two shares are compared as two binomial samples, at
    their pooled share p̄ = (N·p_obs + n·p_model)/(N + n), σ² = p̄(1 − p̄)·(1/N +
    1/n) (Pearson's χ² of the 2×2 table of counts, finite unless both shares
    are 0 or both 1).

    Parameters
    ----------
    p_model : array_like
        The model's p at every point of ``data`` (same order).
    data : MeasuredCuboids
        Default the Gazette note's Table 1.
    model_n : int or array_like, optional
        Throws behind each Monte-Carlo p (None: an exact model).
    points : sequence of float, optional
        The aspect ratios to compare (default all), by their printed value.
    n_fitted : int
        Parameters fitted on these points (subtracted from the degrees of freedom).
    dispersion : float
        φ ≥ 1: the data's variance taken as φ times the binomial (a quasi-binomial
        error model, φ from :func:`dispersion`); the model's own sampling variance
        is kept binomial.
    """
    if not (math.isfinite(dispersion) and dispersion > 0):
        raise ValueError(f"dispersion must be a finite number > 0, got {dispersion!r}")
    pm_all = np.broadcast_to(np.asarray(p_model, dtype=float), data.p.shape)
    if np.any(~np.isfinite(pm_all)) or np.any((pm_all < 0) | (pm_all > 1)):
        raise ValueError("model probabilities must be finite numbers in [0, 1]")
    idx = _point_index(data, points)
    pm = pm_all[idx]
    var = dispersion * pm * (1.0 - pm) / data.n[idx]
    if model_n is not None:
        mn = np.broadcast_to(np.asarray(model_n, dtype=float), data.p.shape)[idx]
        if np.any(~(mn > 0)):
            raise ValueError("model_n must be > 0")
        pooled = (data.n[idx] * data.p[idx] + mn * pm) / (data.n[idx] + mn)
        var = pooled * (1.0 - pooled) * (dispersion / data.n[idx] + 1.0 / mn)
    sigma = np.sqrt(var)
    diff = data.p[idx] - pm
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(sigma > 0, diff / sigma, np.where(diff == 0, 0.0, np.copysign(np.inf, diff)))
    chi2 = float(np.sum(z * z))
    dof = len(idx) - int(n_fitted)
    p_value = float(stats.chi2.sf(chi2, dof)) if dof > 0 else math.nan
    return Comparison(aspect=data.aspect[idx], p_obs=data.p[idx], n=data.n[idx], p_model=pm, sigma=sigma, z=z,
                      chi2=chi2, dof=dof, p_value=p_value)


@dataclasses.dataclass(frozen=True)
class Dispersion:
    """How much more than binomially measured shares scatter about a smooth curve of the aspect ratio.

    Attributes
    ----------
    degree : int
        Degree of the polynomial in ln(x/y) fitted to logit p.
    phi : float
        Pearson's χ² of the data about the fitted curve over its degrees of
        freedom: the quasi-binomial dispersion (1 for binomial scatter).
    chi2 : float
    dof : int
        Points less the degree + 1 coefficients.
    p_value : float
        P(χ²_dof ≥ chi2) for binomial scatter about the curve.
    p_curve : numpy.ndarray
        The fitted curve at the measured points.
    """

    degree: int
    phi: float
    chi2: float
    dof: int
    p_value: float
    p_curve: np.ndarray


def dispersion(data: MeasuredCuboids = GAZETTE_97_16, degree: int = 3) -> Dispersion:
    """The data's scatter about a smooth curve: logit p a polynomial of ``degree`` in ln(x/y), fitted by maximum
    binomial likelihood (Newton's method on the logistic regression, converged to machine precision), and
    Pearson's χ²/dof of the counts about it (McCullagh & Nelder's moment estimate of the quasi-binomial φ).

    Which curve is "smooth" is a choice: compare several degrees and quote the spread of φ.
    """
    degree = int(degree)
    n = np.asarray(data.n, dtype=float)
    k = np.asarray(data.p, dtype=float) * n
    dof = len(n) - degree - 1
    if degree < 0 or dof < 1:
        raise ValueError(f"degree must be 0 … {len(n) - 2} for {len(n)} points, got {degree}")
    x = np.log(np.asarray(data.aspect, dtype=float))
    x = (x - x.mean()) / (np.ptp(x) / 2 or 1.0)
    X = np.polynomial.legendre.legvander(x, degree)  # well conditioned on [-1, 1]
    beta = np.zeros(degree + 1)
    beta[0] = special.logit(np.clip(k.sum() / n.sum(), 1e-9, 1 - 1e-9))
    for _ in range(200):
        q = special.expit(X @ beta)
        w = n * q * (1 - q)
        step = np.linalg.solve(X.T @ (X * w[:, None]), X.T @ (k - n * q))
        beta = beta + step
        if np.max(np.abs(step)) < 1e-13 * (1 + np.max(np.abs(beta))):
            break
    else:  # pragma: no cover - the likelihood is concave; only separable data fail (not measured shares)
        raise ValueError("the logistic fit did not converge")
    q = special.expit(X @ beta)
    chi2 = float(np.sum((k - n * q) ** 2 / (n * q * (1 - q))))
    return Dispersion(degree=degree, phi=chi2 / dof, chi2=chi2, dof=dof, p_value=float(stats.chi2.sf(chi2, dof)),
                      p_curve=q)


@dataclasses.dataclass(frozen=True)
class OneParameterFit:
    """A model with one parameter fitted by least χ² on named points, the others kept as predictions.

    Attributes
    ----------
    value : float
        The fitted parameter.
    interval : (float, float)
        Where χ² on the fit points is within 1 of its minimum (a 68 % interval
        for one parameter); an end at the search bound is reported as the bound.
    fit_points : numpy.ndarray
        Aspect ratios the parameter was fitted on.
    on_fit : Comparison
        The fitted model on the fit points (dof = points − 1).
    predicted : Comparison or None
        The fitted model on the other points, which it predicts (None when every point was fitted).
    overall : Comparison
        All points, one parameter fitted (dof = 15 − 1 for the Gazette table).
    """

    value: float
    interval: tuple[float, float]
    fit_points: np.ndarray
    on_fit: Comparison
    predicted: Comparison | None
    overall: Comparison


def fit_one_parameter(model: Callable[[np.ndarray, float], np.ndarray], bounds: tuple[float, float], *,
                      fit_points: Sequence[float], data: MeasuredCuboids = GAZETTE_97_16, model_n=None,
                      log_scale: bool = False) -> OneParameterFit:
    """Fit one parameter θ of ``model(aspect, θ) -> p`` by least χ² (:func:`compare`) on the points ``fit_points``.

    The χ² is scanned on 401 values across ``bounds`` (geometric when
    ``log_scale``), and the best is refined with a bounded Brent search between
    its neighbours, so a χ² with several minima gives the lowest one seen.
    """
    lo, hi = (float(b) for b in bounds)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi) or (log_scale and lo <= 0):
        raise ValueError(f"bounds must be two finite numbers lo < hi (lo > 0 on a log scale), got {bounds!r}")
    idx = _point_index(data, fit_points)
    fit_aspects = data.aspect[idx]

    def chi2_at(theta: float) -> float:
        c = compare(model(data.aspect, theta), data, model_n=model_n, points=fit_aspects)
        return c.chi2

    grid = np.geomspace(lo, hi, 401) if log_scale else np.linspace(lo, hi, 401)
    vals = np.array([chi2_at(t) for t in grid])
    if not np.any(np.isfinite(vals)):
        raise ValueError("the model's χ² is not finite anywhere within the bounds")
    i = int(np.nanargmin(np.where(np.isfinite(vals), vals, np.nan)))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    res = optimize.minimize_scalar(chi2_at, bounds=(a, b), method="bounded", options={"xatol": 1e-12 * max(1.0, abs(b))})
    best, chi2_min = (float(res.x), float(res.fun)) if res.fun <= vals[i] else (float(grid[i]), float(vals[i]))

    def edge(end: float) -> float:
        if chi2_at(end) - chi2_min < 1.0:
            return end
        return float(optimize.brentq(lambda t: chi2_at(t) - chi2_min - 1.0, *sorted((best, end)), xtol=1e-12))

    p_best = model(data.aspect, best)
    rest = [a for j, a in enumerate(data.aspect) if j not in set(idx.tolist())]
    return OneParameterFit(
        value=best,
        interval=(edge(lo), edge(hi)),
        fit_points=fit_aspects,
        on_fit=compare(p_best, data, model_n=model_n, points=fit_aspects, n_fitted=1),
        predicted=compare(p_best, data, model_n=model_n, points=rest) if rest else None,
        overall=compare(p_best, data, model_n=model_n, n_fitted=1),
    )


def face_counts(outcome) -> dict:
    """The faces of throws' ``outcome`` codes (1..6 a face, 0 an edge, < 0 no end): each face's count and the 95 %
    Wilson interval of its share among the throws that ended on a face (NaN when none did), and the throws that
    ended on an edge or not at all."""
    from .grouping import wilson_interval

    outcome = np.asarray(outcome)
    faces = np.array([int(np.sum(outcome == f)) for f in range(1, 7)])
    n = int(faces.sum())
    lo, hi = wilson_interval(faces, n) if n else (np.full(6, np.nan), np.full(6, np.nan))
    return {"faces": faces.tolist(), "ci_low": np.asarray(lo, dtype=float).tolist(),
            "ci_high": np.asarray(hi, dtype=float).tolist(), "edge": int(np.sum(outcome == 0)),
            "unsettled": int(np.sum(outcome < 0))}


# -- how many throws to see a bias ----------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class DetectionPlan:
    """The number of throws a test needs to detect a bias.

    Attributes
    ----------
    n : int
        The smallest number of throws with power ≥ ``power`` (see :func:`throws_to_detect`).
    test : str
        ``"chi2"`` or ``"binomial"``.
    alpha, power : float
        Level of the test and the power asked for.
    power_at_n : float
        The test's power at ``n`` throws.
    effect : float
        Cohen's w = √Σ(p − p0)²/p0 (``"chi2"``), or p − p0 of the face watched (``"binomial"``).
    face : int or None
        The face watched (``"binomial"``), 1..len(p).
    """

    n: int
    test: str
    alpha: float
    power: float
    power_at_n: float
    effect: float
    face: int | None = None


def _probabilities(p, name: str) -> np.ndarray:
    arr = np.asarray(p, dtype=float)
    if arr.ndim != 1 or arr.size < 2 or np.any(~np.isfinite(arr)) or np.any(arr < 0) or abs(arr.sum() - 1) > 1e-9:
        raise ValueError(f"{name} must be a vector of probabilities that sums to 1, got {p!r}")
    return arr


def _binomial_power(n: np.ndarray, p0: float, p1: float, alpha: float) -> np.ndarray:
    """Exact power of the one-sided binomial test of p = p0 at level alpha, against p1 (the side of p1)."""
    n = np.asarray(n, dtype=np.int64)
    if p1 > p0:  # reject when X >= c, c the smallest count with P0(X >= c) <= alpha
        c = stats.binom.ppf(1.0 - alpha, n, p0) + 1
        return stats.binom.sf(c - 1, n, p1)
    x = stats.binom.ppf(alpha, n, p0)  # reject when X <= c, c the largest count with P0(X <= c) <= alpha
    c = np.where(stats.binom.cdf(x, n, p0) <= alpha, x, x - 1)
    return np.where(c >= 0, stats.binom.cdf(c, n, p1), 0.0)


def throws_to_detect(p, p0=None, *, test: str = "chi2", face: int | None = None, alpha: float = 0.05,
                     power: float = 0.95) -> DetectionPlan:
    """How many throws a player needs to detect that a die's face probabilities are ``p`` and not ``p0``.

    ``test = "chi2"``: Pearson's χ² goodness-of-fit test of ``p0`` (default
    uniform) over all faces at level ``alpha``.  Its power with n throws is
    P(χ'²_{k−1}(λ) > χ²_{k−1, 1−α}) with the non-centrality λ = n·w², Cohen's
    w² = Σ (p − p0)²/p0 (the standard large-sample power of the test; Cohen,
    *Statistical Power Analysis*, 1988, ch. 7).  The power grows with λ, so
    n = ⌈λ*/w²⌉ with λ* the root of power(λ) = ``power``.

    ``test = "binomial"``: the exact one-sided binomial test that one face
    (``face``, 1-based; default the face with the largest |p − p0|) comes up
    with probability p0, rejected on the side of the bias at level ``alpha``.
    Its exact power is not monotone in n (a saw-tooth, as the critical count
    is an integer): n is the smallest number of throws whose power reaches
    ``power``, searched below the point that bisection on the exact power
    brackets, within 50·√n + 100 throws of it.
    """
    p = _probabilities(p, "p")
    p0 = np.full(p.size, 1.0 / p.size) if p0 is None else _probabilities(p0, "p0")
    if p0.shape != p.shape or np.any(p0 <= 0):
        raise ValueError("p0 must have the length of p and no zero probability")
    if not (0 < alpha < 1) or not (alpha < power < 1):
        raise ValueError(f"need 0 < alpha < power < 1, got alpha={alpha!r}, power={power!r}")
    if test == "chi2":
        w2 = float(np.sum((p - p0) ** 2 / p0))
        if w2 == 0:
            raise ValueError("p equals p0: there is no bias to detect")
        df = p.size - 1
        crit = stats.chi2.isf(alpha, df)

        def pw(lam):
            return stats.ncx2.sf(crit, df, lam)

        hi = 1.0
        while pw(hi) < power:
            hi *= 2.0
        lam = optimize.brentq(lambda x: pw(x) - power, 0.0, hi, xtol=1e-12)
        n = max(1, math.ceil(lam / w2))
        while pw(n * w2) < power:  # rounding of lam / w2
            n += 1
        return DetectionPlan(n=n, test=test, alpha=alpha, power=power, power_at_n=float(pw(n * w2)),
                             effect=math.sqrt(w2))
    if test != "binomial":
        raise ValueError(f"test must be 'chi2' or 'binomial', got {test!r}")
    if face is None:
        face = int(np.argmax(np.abs(p - p0))) + 1
    if not (1 <= face <= p.size):
        raise ValueError(f"face must be in 1..{p.size}, got {face!r}")
    q0, q1 = float(p0[face - 1]), float(p[face - 1])
    if q0 == q1:
        raise ValueError(f"face {face} has the same probability under p and p0: no bias to detect on it")

    def pw_at(n: int) -> float:
        return float(_binomial_power(np.array([n]), q0, q1, alpha)[0])

    hi = 1
    while pw_at(hi) < power:
        hi *= 2
    lo_n = hi // 2
    while hi - lo_n > 1:  # bisection on the (nearly monotone) exact power
        mid = (lo_n + hi) // 2
        if pw_at(mid) >= power:
            hi = mid
        else:
            lo_n = mid
    start = max(1, hi - int(50 * math.sqrt(hi)) - 100)
    ns = np.arange(start, hi + 1)
    powers = _binomial_power(ns, q0, q1, alpha)
    n = int(ns[np.argmax(powers >= power)])
    return DetectionPlan(n=n, test=test, alpha=alpha, power=power, power_at_n=pw_at(n), effect=q1 - q0, face=face)
