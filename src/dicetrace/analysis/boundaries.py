"""Basin boundaries: boundary fraction, dimension and basin entropy, and the power-law fit they share.

The uncertainty exponent is in :mod:`dicetrace.analysis.uncertainty` and the
Wada tests, which build on :func:`boundary_mask`, in
:mod:`dicetrace.analysis.wada`.

All grid functions take a label grid (2-D ``(nx, ny)`` or 3-D) whose nodes are
equally spaced; sizes (``box_size``, ``box_sizes``, ``r``) are in grid nodes
in every function, as in Attractors.jl (a box of ``b`` nodes a side).  The
closed boxes of :func:`boundary_box_fraction`, ``uncertainty_exponent``
and :func:`boundary_dimension` share their faces, so they span ``b - 1``
intervals and ``eps = (b - 1)`` spacings; the disjoint boxes of
:func:`box_counting_dimension` and :func:`basin_entropy` tile ``b`` nodes. Labels 0 ("undefined") and -1 ("did not settle") are labels of their
own unless ``exclude`` is given.

Relations used throughout (Grebogi, McDonald, Ott & Yorke 1983, Phys. Lett. A
99:415; McDonald et al. 1985, Physica D 17:125): the fraction ``f(eps)`` of
initial conditions that an error of size ``eps`` can send to another basin
scales as ``f ~ eps**alpha`` (the uncertainty exponent), and
``alpha = d - D`` with ``d`` the dimension of the space and ``D`` the
box-counting dimension of the boundary. A smooth boundary has ``alpha = 1``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Hashable, Iterable, Sequence

import numpy as np
from scipy import stats

from ._grid import as_label_grid, boxes, closed_box_minmax, encode_labels, neighbour_offsets, shifted_pair

__all__ = [
    "PowerLawFit",
    "BoxCountingDimension",
    "BasinEntropy",
    "boundary_mask",
    "boundary_fraction",
    "boundary_box_fraction",
    "box_counting_dimension",
    "boundary_dimension",
    "basin_entropy",
    "fit_power_law",
]


# --------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class PowerLawFit:
    """Least-squares line through ``(log x, log y)``: ``y = exp(intercept) x**slope``."""

    slope: float
    slope_stderr: float
    intercept: float
    rvalue: float
    n: int


def fit_power_law(x, y, *, weights=None) -> PowerLawFit:
    """Fit ``y ~ x**slope`` by least squares in log-log.

    Parameters
    ----------
    x, y : array_like
        Positive values; pairs with ``y <= 0`` or non-finite values are dropped.
    weights : array_like, optional
        Weights of the points (inverse variances of ``log y``); weighted least
        squares with the standard error scaled by the weighted residuals
        (as statsmodels ``WLS``). Default: ordinary least squares
        (``scipy.stats.linregress``).

    Returns
    -------
    PowerLawFit
        ``slope_stderr`` is the regression's standard error (``nan`` for
        fewer than 3 points).
    """
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    w = None if weights is None else np.asarray(weights, dtype=float).ravel()
    ok = (x > 0) & (y > 0) & np.isfinite(x) & np.isfinite(y)
    if w is not None:
        ok &= np.isfinite(w) & (w > 0)
    x, y = x[ok], y[ok]
    if len(x) < 2:
        raise ValueError("need at least two positive points to fit a power law")
    lx, ly = np.log(x), np.log(y)
    if len(x) == 2:
        slope = (ly[1] - ly[0]) / (lx[1] - lx[0])
        return PowerLawFit(float(slope), math.nan, float(ly[0] - slope * lx[0]), 1.0, 2)
    if w is None:
        res = stats.linregress(lx, ly)
        return PowerLawFit(
            float(res.slope), float(res.stderr), float(res.intercept), float(res.rvalue), len(x)
        )
    w = w[ok]
    X = np.column_stack([np.ones_like(lx), lx])
    xtwx = X.T @ (w[:, None] * X)
    beta = np.linalg.solve(xtwx, X.T @ (w * ly))
    resid = ly - X @ beta
    s2 = float(np.sum(w * resid**2) / (len(x) - 2))
    cov = s2 * np.linalg.inv(xtwx)
    r = float(np.corrcoef(lx, ly)[0, 1])
    return PowerLawFit(float(beta[1]), float(np.sqrt(cov[1, 1])), float(beta[0]), r, len(x))


@dataclasses.dataclass(frozen=True)
class BoxCountingDimension:
    """Box-counting dimension ``D`` from ``N(b) ~ b**-D``.

    Attributes
    ----------
    dimension, stderr : float
    box_sizes : numpy.ndarray
        Box sides (grid nodes).
    counts : numpy.ndarray
        Number of occupied boxes at each side.
    """

    dimension: float
    stderr: float
    box_sizes: np.ndarray
    counts: np.ndarray


@dataclasses.dataclass(frozen=True)
class BasinEntropy:
    """Basin entropy ``Sb`` and boundary basin entropy ``Sbb`` (nats).

    Attributes
    ----------
    Sb : float
        Mean Gibbs entropy over all boxes.
    Sbb : float
        Mean entropy over the boxes holding >= 2 labels (``nan`` if none).
    box_size : int
    n_boxes, n_boundary_boxes : int
    box_entropies : numpy.ndarray
        Entropy of every box (for bootstrap error bars).
    n_labels : int
        Number of distinct labels in the grid.
    """

    Sb: float
    Sbb: float
    box_size: int
    n_boxes: int
    n_boundary_boxes: int
    box_entropies: np.ndarray
    n_labels: int

    @property
    def fractal_boundary(self) -> bool:
        """``Sbb > ln 2``: sufficient (not necessary) for a fractal boundary.

        Daza et al. (2016), Sci. Rep. 6:31416. With two labels ``Sbb <= ln 2``
        always, so the criterion can only fire with three labels or more.
        """
        return bool(self.Sbb > math.log(2))


# --------------------------------------------------------------------------
# boundary mask and fractions
# --------------------------------------------------------------------------


def boundary_mask(grid, *, connectivity: str = "face") -> np.ndarray:
    """Nodes with at least one neighbour of a different label.

    Parameters
    ----------
    grid : array_like, 2-D or 3-D
        Label grid.
    connectivity : {"face", "full"}, optional
        Neighbours sharing a face (default) or also edges/corners.

    Returns
    -------
    numpy.ndarray of bool, same shape
        Both sides of every label change are marked.
    """
    arr = as_label_grid(grid, ndim=(1, 2, 3))
    codes, _ = encode_labels(arr)
    mask = np.zeros(arr.shape, dtype=bool)
    for off in neighbour_offsets(arr.ndim, connectivity):
        sa, sb = shifted_pair(codes, off)
        diff = codes[sa] != codes[sb]
        mask[sa] |= diff
        mask[sb] |= diff
    return mask


def boundary_fraction(grid, *, connectivity: str = "face") -> float:
    """Fraction of grid nodes that are boundary nodes (see :func:`boundary_mask`).

    At grid spacing ``h`` this is the uncertain fraction ``f(h)`` of the
    nearest-neighbour perturbation; comparing grids of one window at several
    resolutions gives ``f(h) ~ h**alpha``.
    """
    return float(boundary_mask(grid, connectivity=connectivity).mean())


def _box_label_stats(codes: np.ndarray, box_size: int) -> tuple[int, int]:
    lo, hi = closed_box_minmax(codes, box_size)
    return int((lo != hi).sum()), int(lo.size)


def boundary_box_fraction(grid, box_size: int) -> float:
    """Fraction of ``box_size``-sided boxes that hold two labels or more.

    Parameters
    ----------
    grid : array_like, 2-D or 3-D
        Label grid.
    box_size : int
        Box side in grid nodes (>= 2). Boxes are closed: box ``k`` spans nodes
        ``k (b - 1) .. (k + 1)(b - 1)`` along each axis, so neighbouring boxes
        share a face and no label change between two nodes is missed. Boxes
        reaching past the grid are dropped.

    Returns
    -------
    float
    """
    codes, _ = encode_labels(as_label_grid(grid))
    nu, nb = _box_label_stats(codes, box_size)
    return nu / nb


#: How many box sizes the default range holds at most (geometrically spaced).
DEFAULT_N_BOX_SIZES = 12


def _default_box_sizes(shape) -> np.ndarray:
    """Attractors.jl's range, 2 .. max(shape)//20 nodes (at least 2..5), thinned to at most
    ``DEFAULT_N_BOX_SIZES`` geometrically spaced sizes: each size costs one pass over the grid,
    so the full range would cost O(n³) on an n×n grid, the thinned one O(n² log n)."""
    hi = max(5, max(shape) // 20)
    hi = min(hi, max(2, min(shape) // 2))
    sizes = np.unique(np.round(np.geomspace(2, hi, DEFAULT_N_BOX_SIZES)).astype(int))
    return sizes if len(sizes) >= min(4, hi - 1) else np.arange(2, hi + 1)


# --------------------------------------------------------------------------
# dimension
# --------------------------------------------------------------------------


def box_counting_dimension(mask, *, box_sizes: Sequence[int] | None = None) -> BoxCountingDimension:
    """Box-counting dimension of a set given as a boolean grid.

    Parameters
    ----------
    mask : array_like of bool, 1-D, 2-D or 3-D
        The set (e.g. :func:`boundary_mask`).
    box_sizes : sequence of int, optional
        Box sides in grid nodes, default as :func:`uncertainty_exponent`.

    Returns
    -------
    BoxCountingDimension
        ``D`` from a least-squares fit of ``log N(b)`` against ``log(1/b)``,
        with ``N(b)`` scaled by the fraction of the grid the whole boxes cover
        (``counts`` holds the raw numbers).
    """
    m = np.asarray(mask, dtype=bool)
    sizes = np.asarray(_default_box_sizes(m.shape) if box_sizes is None else list(box_sizes))
    counts = np.array([int(boxes(m, int(b)).any(axis=1).sum()) for b in sizes])
    # the boxes cover (n // b) * b nodes per axis: scale to the whole grid
    cover = np.array([np.prod([(n // int(b)) * int(b) / n for n in m.shape]) for b in sizes])
    fit = fit_power_law(sizes, counts / cover)
    return BoxCountingDimension(-fit.slope, fit.slope_stderr, sizes, counts)


def boundary_dimension(
    grid,
    *,
    box_sizes: Sequence[int] | None = None,
    method: str = "labels",
    connectivity: str = "face",
) -> BoxCountingDimension:
    """Box-counting dimension of the boundary of a label grid.

    Parameters
    ----------
    grid : array_like, 2-D or 3-D
    box_sizes : sequence of int, optional
        Box sides in grid nodes.
    method : {"labels", "mask"}, optional
        ``"labels"`` (default): count boxes holding two labels or more
        (Attractors.jl ``basins_fractal_dimension``; equals ``d - alpha`` of
        :func:`uncertainty_exponent` with the same boxes). ``"mask"``: count
        boxes holding a node of :func:`boundary_mask`.
    connectivity : {"face", "full"}, optional
        For ``method="mask"``.

    Returns
    -------
    BoxCountingDimension
    """
    arr = as_label_grid(grid)
    if method == "mask":
        return box_counting_dimension(boundary_mask(arr, connectivity=connectivity), box_sizes=box_sizes)
    if method != "labels":
        raise ValueError(f"method must be 'labels' or 'mask', not {method!r}")
    codes, _ = encode_labels(arr)
    sizes = np.asarray(_default_box_sizes(arr.shape) if box_sizes is None else list(box_sizes))
    counts = np.array([_box_label_stats(codes, int(b))[0] for b in sizes])
    # closed boxes of b nodes span b - 1 intervals and cover ((n - 1) // (b - 1)) (b - 1)
    # of the n - 1 intervals per axis
    span = sizes - 1
    cover = np.array(
        [np.prod([((n - 1) // int(s)) * int(s) / (n - 1) for n in arr.shape]) for s in span]
    )
    fit = fit_power_law(span, counts / cover)
    return BoxCountingDimension(-fit.slope, fit.slope_stderr, sizes, counts)


# --------------------------------------------------------------------------
# basin entropy
# --------------------------------------------------------------------------


def basin_entropy(
    grid, box_size: int = 5, *, exclude: Iterable[Hashable] = ()
) -> BasinEntropy:
    """Basin entropy ``Sb`` and boundary basin entropy ``Sbb``.

    Parameters
    ----------
    grid : array_like, 2-D or 3-D
        Label grid.
    box_size : int, optional
        Box side in grid nodes (Daza et al. use 5); the grid is tiled from
        index 0 and incomplete edge boxes are dropped.
    exclude : iterable, optional
        Labels whose nodes are ignored within each box (a box of excluded
        nodes only has entropy 0).

    Returns
    -------
    BasinEntropy
        ``Sb = mean_i S_i`` over all boxes and ``Sbb`` over boxes with
        ``S_i > 0``, where ``S_i = -sum_j p_ij ln p_ij`` (nats) and ``p_ij`` is
        the fraction of box ``i``'s nodes with label ``j``.

    Notes
    -----
    Daza, Wagemakers, Georgeot, Guéry-Odelin & Sanjuán (2016), "Basin
    entropy: a new tool to analyze uncertainty in dynamical systems",
    Sci. Rep. 6:31416. ``Sbb > ln 2`` is a sufficient condition for a fractal
    boundary (:attr:`BasinEntropy.fractal_boundary`); :func:`basins_fractal_test`
    is the sharper test. For a straight boundary *parallel to a box side*,
    crossing it at a uniformly random position, ``Sbb -> 1/2`` (the mean of the
    binary entropy over ``p ~ U(0, 1)``); a tilted line cuts boxes into
    fractions that are not uniform (corner triangles are more likely), and
    gives less: at 45 degrees about 0.37 for large boxes (0.45 at 5 nodes;
    on a grid the axis-parallel line gives 0.58 at 5 nodes, 0.52 at 40).
    """
    arr = as_label_grid(grid)
    codes, uniques = encode_labels(arr)
    excl = set(exclude)
    integer = arr.dtype.kind in "iub"
    bx = boxes(codes, int(box_size))
    kept_codes = [
        (u if integer else i) for i, u in enumerate(uniques) if u not in excl
    ]
    counts = np.stack([(bx == c).sum(axis=1) for c in kept_codes], axis=1).astype(float)
    tot = counts.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = np.where(tot > 0, counts / np.where(tot > 0, tot, 1), 0.0)
        ent = -np.where(p > 0, p * np.log(np.where(p > 0, p, 1.0)), 0.0).sum(axis=1)
    ent = np.where(ent < 1e-15, 0.0, ent)
    boundary = ent > 0
    nbb = int(boundary.sum())
    return BasinEntropy(
        Sb=float(ent.mean()),
        Sbb=float(ent[boundary].mean()) if nbb else math.nan,
        box_size=int(box_size),
        n_boxes=int(len(ent)),
        n_boundary_boxes=nbb,
        box_entropies=ent,
        n_labels=len(kept_codes),
    )
