"""The Wada property of basins: the merging test and the refinement of boundary segments.

Kept apart from :mod:`dicetrace.analysis.boundaries` (as Attractors.jl keeps
``wada_test.jl`` apart from ``fractality_of_basins.jl``): two tests of
whether every boundary point of one basin is a boundary point of all,

- :func:`wada_merge_test`, on a label grid alone (Daza, Wagemakers & Sanjuán
  2018, the merging method);
- :func:`wada_grid_test`, refining the grid's boundary segments with a
  ``classify(points) -> labels`` callable (after Daza, Wagemakers, Sanjuán &
  Yorke 2015, the grid method).

Labels 0 ("undefined") and -1 ("did not settle") are labels of their own
unless ``exclude`` is given.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Hashable, Iterable, Sequence

import numpy as np
from scipy import ndimage

from ._grid import as_label_grid, encode_labels, shifted_pair
from .boundaries import boundary_mask

__all__ = ["WadaMergeResult", "WadaGridResult", "wada_merge_test", "wada_grid_test"]


@dataclasses.dataclass(frozen=True)
class WadaMergeResult:
    """Result of :func:`wada_merge_test`.

    Attributes
    ----------
    labels : tuple
        Labels tested.
    r : numpy.ndarray
        Distances 0..r_max (grid nodes, chessboard metric).
    far_fraction : numpy.ndarray
        ``W(r)``: over all ordered pairs ``(k, j)`` of labels, the largest
        fraction of nodes of the merged boundary of ``k`` that lie farther
        than ``r`` from the merged boundary of ``j``.
    r_wada : int or None
        Smallest ``r`` with ``W(r) <= tol``.
    tol : float
    """

    labels: tuple
    r: np.ndarray
    far_fraction: np.ndarray
    r_wada: int | None
    tol: float

    @property
    def wada(self) -> bool:
        return self.r_wada is not None


def wada_merge_test(
    grid,
    *,
    r_max: int = 5,
    tol: float = 0.01,
    exclude: Iterable[Hashable] = (),
) -> WadaMergeResult:
    """Wada property of a label grid by the merging method.

    For every label ``k`` the grid is merged into two basins, ``k`` and
    "not k"; the boundary of that two-basin picture is ``B_k`` (both sides of
    every change, face neighbours). The basins are Wada when all ``B_k``
    coincide: every point of the boundary of one basin is on the boundary of
    all. At grid resolution ``B_k`` and ``B_j`` coincide up to a few nodes, so
    the test refines ``r = 0, 1, ..., r_max`` and reports the smallest ``r``
    at which at most a fraction ``tol`` of any ``B_k`` lies farther than ``r``
    (chessboard distance) from any other ``B_j``.

    Parameters
    ----------
    grid : array_like, 2-D or 3-D
        Label grid with at least three labels (after ``exclude``).
    r_max : int, optional
        Largest distance tried (grid nodes). A single triple point fails at
        every ``r`` much smaller than the grid.
    tol : float, optional
        Allowed far fraction (numerical leftovers such as unresolved
        filaments), default 0.01.
    exclude : iterable, optional
        Labels not tested (their nodes count as "not k" for every k).

    Returns
    -------
    WadaMergeResult

    Notes
    -----
    Daza, Wagemakers & Sanjuán (2018), "Ascertaining when a basin is Wada:
    the merging method", Sci. Rep. 8:9954; Attractors.jl ``test_wada_merge``
    (which normalises by the whole grid; here the fraction is of the boundary
    nodes).
    """
    arr = as_label_grid(grid)
    codes, uniques = encode_labels(arr)
    integer = arr.dtype.kind in "iub"
    excl = set(exclude)
    labs = [u for u in uniques if u not in excl]
    if len(labs) < 3:
        raise ValueError(f"the Wada test needs at least 3 labels, got {labs!r}")
    bnd, dist = [], []
    for i, u in enumerate(uniques):
        if u in excl:
            continue
        b = boundary_mask(codes == (u if integer else i))
        bnd.append(b)
        dist.append(ndimage.distance_transform_cdt(~b, metric="chessboard") if b.any() else None)
    rs = np.arange(int(r_max) + 1)
    far = np.zeros(len(rs))
    for a, ba in enumerate(bnd):
        na = int(ba.sum())
        if na == 0:
            continue
        for c, dc in enumerate(dist):
            if a == c:
                continue
            if dc is None:
                far[:] = 1.0
                continue
            dvals = dc[ba]
            frac = (dvals[None, :] > rs[:, None]).mean(axis=1)
            far = np.maximum(far, frac)
    ok = np.nonzero(far <= tol)[0]
    return WadaMergeResult(
        labels=tuple(labs),
        r=rs,
        far_fraction=far,
        r_wada=int(rs[ok[0]]) if len(ok) else None,
        tol=float(tol),
    )


@dataclasses.dataclass(frozen=True)
class WadaGridResult:
    """Result of :func:`wada_grid_test`.

    Attributes
    ----------
    labels : tuple
        Labels counted (all labels of the grid, minus ``exclude``).
    levels : numpy.ndarray
        Refinement levels 0..max_level.
    wada_fraction : numpy.ndarray
        ``G(q)``: fraction of the tested boundary segments on which all labels
        have been found after ``q`` levels of bisection.
    n_segments : int
    n_evals : int
        Calls of ``classify`` per point (total points classified).
    threshold : float
    """

    labels: tuple
    levels: np.ndarray
    wada_fraction: np.ndarray
    n_segments: int
    n_evals: int
    threshold: float

    @property
    def wada(self) -> bool:
        return bool(self.wada_fraction[-1] >= self.threshold)


def wada_grid_test(
    classify: Callable[[np.ndarray], np.ndarray],
    grid,
    extent: Sequence[tuple[float, float]],
    *,
    max_level: int = 24,
    max_segments: int | None = 2000,
    threshold: float = 0.95,
    exclude: Iterable[Hashable] = (),
    rng: np.random.Generator | None = None,
) -> WadaGridResult:
    """Wada property by refining boundary segments with the classifier.

    Every pair of face-neighbouring grid nodes with different labels is a
    boundary segment. Each segment is refined by bisection with ``classify``:
    at every level, the sub-segments whose ends differ get their midpoint
    classified. A segment is *Wada* at level ``q`` once all labels of the
    grid have appeared on it. For Wada basins ``G(q) -> 1``; a boundary
    between two basins only (away from a triple point) never shows the third
    label, whatever the refinement.

    Parameters
    ----------
    classify : callable
        ``classify(points (n, 2)) -> labels (n,)``, slice coordinates.
    grid : array_like, shape (nx, ny)
        Labels of the grid nodes (as produced by ``classify`` on the grid).
    extent : sequence of (lo, hi)
        ``[(x0, x1), (y0, y1)]``: slice coordinates of the first/last nodes.
    max_level : int, optional
        Bisection levels (a segment gets at most ``2**max_level - 1`` new
        points).
    max_segments : int or None, optional
        Random subset of boundary segments tested (``None``: all).
    threshold : float, optional
        ``G(max_level) >= threshold`` is reported as Wada.
    exclude : iterable, optional
        Labels not required on a segment.
    rng : numpy.random.Generator, optional
        For the segment subset.

    Returns
    -------
    WadaGridResult

    Notes
    -----
    A one-dimensional version of the grid method of Daza, Wagemakers, Sanjuán
    & Yorke (2015), "Testing for basins of Wada", Sci. Rep. 5:16579, which
    refines boundary boxes; here the boxes are the grid edges between nodes of
    different labels.
    """
    arr = as_label_grid(grid, ndim=(2,))
    ext = np.asarray(extent, dtype=float)
    nx, ny = arr.shape
    hx = (ext[0, 1] - ext[0, 0]) / max(nx - 1, 1)
    hy = (ext[1, 1] - ext[1, 0]) / max(ny - 1, 1)
    codes, uniques = encode_labels(arr)
    excl = set(exclude)
    labs = [u for u in uniques if u not in excl]
    if len(labs) < 3:
        raise ValueError(f"the Wada test needs at least 3 labels, got {labs!r}")
    lab_index = {u: q for q, u in enumerate(labs)}
    full = (1 << len(labs)) - 1

    def bit(values) -> np.ndarray:
        return np.array([1 << lab_index[v] if v in lab_index else 0 for v in values], dtype=np.int64)

    segs_a, segs_b = [], []
    for off in ((1, 0), (0, 1)):
        sa, sb = shifted_pair(codes, off)
        ia = np.argwhere(codes[sa] != codes[sb])
        segs_a.append(ia + [s.start for s in sa])
        segs_b.append(ia + [s.start for s in sb])
    ia = np.concatenate(segs_a)
    ib = np.concatenate(segs_b)
    if max_segments is not None and len(ia) > max_segments:
        rng = np.random.default_rng() if rng is None else rng
        pick = rng.choice(len(ia), size=max_segments, replace=False)
        ia, ib = ia[pick], ib[pick]
    nseg = len(ia)
    if nseg == 0:
        raise ValueError("the grid has no boundary")
    to_xy = lambda ij: np.stack([ext[0, 0] + ij[:, 0] * hx, ext[1, 0] + ij[:, 1] * hy], axis=1)
    pa, pb = to_xy(ia.astype(float)), to_xy(ib.astype(float))
    la = np.array([arr[tuple(p)] for p in ia], dtype=object)
    lb = np.array([arr[tuple(p)] for p in ib], dtype=object)
    seen = bit(la) | bit(lb)
    g = [float(np.mean(seen == full))]
    # active sub-segments: (segment id, end a, end b, label a, label b)
    sid = np.arange(nseg)
    n_evals = 0
    for _ in range(max_level):
        active = la != lb
        if not active.any():
            g.append(g[-1])
            continue
        sid, pa, pb, la, lb = sid[active], pa[active], pb[active], la[active], lb[active]
        # segments already Wada need no more points
        keep = seen[sid] != full
        sid, pa, pb, la, lb = sid[keep], pa[keep], pb[keep], la[keep], lb[keep]
        if len(sid) == 0:
            g.append(float(np.mean(seen == full)))
            continue
        mid = 0.5 * (pa + pb)
        lm = np.asarray(classify(mid), dtype=object).ravel()
        n_evals += len(mid)
        np.bitwise_or.at(seen, sid, bit(lm))
        sid = np.concatenate([sid, sid])
        pa, pb = np.concatenate([pa, mid]), np.concatenate([mid, pb])
        la, lb = np.concatenate([la, lm]), np.concatenate([lm, lb])
        g.append(float(np.mean(seen == full)))
    return WadaGridResult(
        labels=tuple(labs),
        levels=np.arange(max_level + 1),
        wada_fraction=np.array(g),
        n_segments=nseg,
        n_evals=n_evals,
        threshold=float(threshold),
    )
