"""The uncertainty exponent α of a map's borders: how the fraction of points an error can move scales with it.

The fraction ``f(eps)`` of initial conditions that an error of size ``eps``
can send to another basin scales as ``f ~ eps**alpha`` (Grebogi, McDonald,
Ott & Yorke 1983, Phys. Lett. A 99:415; McDonald et al. 1985, Physica D
17:125), and ``alpha = d - D`` with ``d`` the dimension of the space and ``D``
the box-counting dimension of the boundary; a smooth boundary has
``alpha = 1``.  Three ways to measure it, as Attractors.jl has them:
:func:`uncertainty_exponent` from boxes of a label grid (sizes in grid
nodes, closed boxes that share their faces, as in
:mod:`dicetrace.analysis.boundaries`), :func:`uncertainty_exponent_resolution`
from a series of grids of one window at several resolutions, and
:func:`uncertainty_exponent_perturbation` from pairs of points a distance
``eps`` apart, classified anew (a ``classify(points) -> labels`` callable).
Each returns an :class:`UncertaintyExponent`; the fit is
:func:`~dicetrace.analysis.boundaries.fit_power_law`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from ._grid import as_label_grid, encode_labels
from .boundaries import _box_label_stats, _default_box_sizes, boundary_fraction, boundary_mask, fit_power_law

__all__ = ["UncertaintyExponent", "uncertainty_exponent", "uncertainty_exponent_perturbation",
           "uncertainty_exponent_resolution"]


@dataclasses.dataclass(frozen=True)
class UncertaintyExponent:
    """Uncertainty exponent ``alpha`` of ``f(eps) ~ eps**alpha``.

    Attributes
    ----------
    alpha, alpha_stderr : float
        Slope of ``log f`` against ``log eps`` and its regression standard error.
    eps : numpy.ndarray
        Scales used (slice units when a spacing was given, else grid nodes).
    f : numpy.ndarray
        Uncertain fraction at each scale.
    ndim : int
        Dimension ``d`` of the sampled space.
    dimension : float
        Implied box-counting dimension of the boundary, ``d - alpha``.
    method : str
    n : numpy.ndarray or None
        Trials behind each ``f`` (boxes or point pairs).
    """

    alpha: float
    alpha_stderr: float
    eps: np.ndarray
    f: np.ndarray
    ndim: int
    method: str
    intercept: float = math.nan
    n: np.ndarray | None = None

    @property
    def dimension(self) -> float:
        return self.ndim - self.alpha

    @classmethod
    def fit(cls, eps, f, *, ndim: int, method: str, n=None, weights=None) -> "UncertaintyExponent":
        """Fit ``f ~ eps**alpha`` (:func:`fit_power_law`, optionally weighted) and hold the result."""
        fit = fit_power_law(eps, f, weights=weights)
        return cls(alpha=fit.slope, alpha_stderr=fit.slope_stderr, eps=eps, f=f, ndim=ndim, method=method,
                   intercept=fit.intercept, n=n)


def uncertainty_exponent(
    grid,
    *,
    box_sizes: Sequence[int] | None = None,
    spacing: float = 1.0,
    method: str = "boxes",
) -> UncertaintyExponent:
    """Uncertainty exponent of a label grid.

    Parameters
    ----------
    grid : array_like, 2-D or 3-D
        Label grid; ``f(eps)`` is the fraction of its boxes of side ``eps``
        (method ``"boxes"``) or of its subsampled nodes that are uncertain.
    box_sizes : sequence of int, optional
        Box sides (method ``"boxes"``) or strides (``"subsample"``) in grid
        nodes. Default: Attractors.jl's range ``2 .. max(shape)//20`` (at
        least ``2..5``), thinned to at most 12 geometrically spaced sizes.
    spacing : float, optional
        Grid spacing in slice units, only to express ``eps`` in slice units:
        ``eps = (b - 1) * spacing`` for a closed box of ``b`` nodes (its side),
        ``eps = b * spacing`` for the stride ``b`` of ``"subsample"``.
    method : {"boxes", "subsample"}, optional
        ``"boxes"`` (default): ``f(eps)`` is the fraction of boxes of side
        ``eps`` that hold two labels or more (:func:`boundary_box_fraction`;
        as Attractors.jl ``uncertainty_exponent``, ``alpha = d - D`` by box
        counting). The boxes are closed, sharing their faces; Attractors.jl
        tiles disjoint boxes, which misses the changes between boxes
        (a factor ``(b - 1) / b``) and biases ``alpha`` up at small ``b``.
        ``"subsample"``: ``f(eps)`` is the boundary-node fraction of the grid
        subsampled every ``eps`` nodes, i.e. the fraction of initial
        conditions whose nearest neighbour at distance ``eps`` differs.

    Returns
    -------
    UncertaintyExponent

    Notes
    -----
    Grebogi, McDonald, Ott & Yorke (1983), Phys. Lett. A 99:415; a straight
    boundary gives ``alpha = 1``, a fractal one ``alpha = d - D < 1``.
    """
    arr = as_label_grid(grid)
    codes, _ = encode_labels(arr)
    sizes = np.asarray(
        _default_box_sizes(arr.shape) if box_sizes is None else list(box_sizes), dtype=int
    )
    if method not in ("boxes", "subsample"):
        raise ValueError(f"method must be 'boxes' or 'subsample', not {method!r}")
    f = np.empty(len(sizes))
    n = np.empty(len(sizes), dtype=np.int64)
    for q, b in enumerate(sizes):
        if method == "boxes":
            nu, nb = _box_label_stats(codes, int(b))
            f[q], n[q] = nu / nb, nb
        else:
            sub = codes[tuple(slice(None, None, int(b)) for _ in range(arr.ndim))]
            m = boundary_mask(sub)
            f[q], n[q] = m.mean(), m.size
    eps = (sizes - 1 if method == "boxes" else sizes) * float(spacing)
    return UncertaintyExponent.fit(eps, f, ndim=arr.ndim, method=method, n=n)


def uncertainty_exponent_resolution(
    grids: Sequence, spacings: Sequence[float], *, connectivity: str = "face"
) -> UncertaintyExponent:
    """Uncertainty exponent from grids of one window at several resolutions.

    Parameters
    ----------
    grids : sequence of array_like
        Label grids of the same window (e.g. scans at 100^2, 200^2, 400^2).
    spacings : sequence of float
        Grid spacing of each, slice units.
    connectivity : {"face", "full"}, optional
        For :func:`boundary_fraction`.

    Returns
    -------
    UncertaintyExponent
        ``f(eps)`` is the boundary-node fraction of the grid with spacing
        ``eps``: the fraction of initial conditions whose neighbour at
        distance ``eps`` ends elsewhere.
    """
    if len(grids) != len(spacings):
        raise ValueError("grids and spacings must have the same length")
    arrs = [as_label_grid(g) for g in grids]
    f = np.array([boundary_fraction(a, connectivity=connectivity) for a in arrs])
    eps = np.asarray(spacings, dtype=float)
    return UncertaintyExponent.fit(eps, f, ndim=arrs[0].ndim, method="resolution",
                                   n=np.array([a.size for a in arrs], dtype=np.int64))


def uncertainty_exponent_perturbation(
    classify: Callable[[np.ndarray], np.ndarray],
    points,
    eps_list: Sequence[float],
    rng: np.random.Generator,
    *,
    labels=None,
    direction: str = "random",
) -> UncertaintyExponent:
    """Uncertainty exponent by random perturbation of initial conditions.

    For every ``eps`` and every point ``p`` the label of ``p + eps * u`` is
    compared with that of ``p``, ``u`` a random unit vector; ``f(eps)`` is the
    fraction of points whose label changes (Grebogi et al. 1983).

    Parameters
    ----------
    classify : callable
        ``classify(points (n, d)) -> labels (n,)``, slice coordinates in.
        Called once for the base points (unless ``labels`` is given) and once
        for all perturbed points together.
    points : array_like, shape (n, d)
        Base points, slice units.
    eps_list : sequence of float
        Perturbation sizes, slice units.
    rng : numpy.random.Generator
    labels : array_like, shape (n,), optional
        Labels of ``points`` if already known.
    direction : {"random", "axis"}, optional
        ``"random"``: isotropic unit vectors. ``"axis"``: +-unit vectors along
        a random coordinate axis.

    Returns
    -------
    UncertaintyExponent
        ``n`` holds the number of point pairs per ``eps``. The fit is weighted
        by the binomial variance of ``log f``; zero fractions are left out.

    Notes
    -----
    Grebogi, McDonald, Ott & Yorke (1983), Phys. Lett. A 99:415 (pairs
    ``p, p + eps``). For a boundary that is the graph of a Hölder-``H``
    function, isotropic directions give ``alpha = H`` (the component along
    the graph dominates), axis directions normal to it give 1.
    """
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    npts, d = pts.shape
    eps_arr = np.asarray(eps_list, dtype=float).ravel()
    base = np.asarray(classify(pts) if labels is None else labels).ravel()
    if direction == "random":
        u = rng.standard_normal((len(eps_arr), npts, d))
        u /= np.linalg.norm(u, axis=2, keepdims=True)
    elif direction == "axis":
        u = np.zeros((len(eps_arr), npts, d))
        ax = rng.integers(0, d, size=(len(eps_arr), npts))
        sign = rng.choice([-1.0, 1.0], size=(len(eps_arr), npts))
        np.put_along_axis(u, ax[..., None], sign[..., None], axis=2)
    else:
        raise ValueError(f"direction must be 'random' or 'axis', not {direction!r}")
    moved = (pts[None] + eps_arr[:, None, None] * u).reshape(-1, d)
    new = np.asarray(classify(moved)).reshape(len(eps_arr), npts)
    f = (new != base[None]).mean(axis=1)
    # binomial variance of log f: (1 - f) / (n f)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where((f > 0) & (f < 1), npts * f / (1 - f), 0.0)
    return UncertaintyExponent.fit(eps_arr, f, ndim=d, method=f"perturbation-{direction}",
                                   n=np.full(len(eps_arr), npts, dtype=np.int64), weights=w)
