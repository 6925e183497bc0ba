"""Vertex hunt (writeup section 4.3 and 5.4).

A *vertex* of the cell structure in a 2-D slice is a point where three or more
cells meet. The writeup zoomed in on candidates and "soon lost the vertex":
the three labels stopped meeting at a point. :func:`find_vertices` automates
the hunt by recursive refinement with the classifier itself (not
interpolation) and reports either the vertex, located to ``tol``, or the scale
at which refinement split the candidate (the labels no longer co-occur in any
child square).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Iterable

import numpy as np
import pandas as pd
from scipy import ndimage

__all__ = ["find_vertices", "guarded_find_vertices", "triple_boxes"]

_COLUMNS = ["root", "status", "x", "y", "size_x", "size_y", "depth", "labels", "n_squares"]


def _hashable(v):
    return v.item() if isinstance(v, np.generic) else v


_NEIGHBOURS = [(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)]


def _clusters(squares) -> list[list[tuple[int, int]]]:
    """8-connected clusters of integer lattice squares, without a dense image.

    Union-find over the set of squares (memory O(number of squares), whatever
    their spread). Clusters come in order of their smallest square, members
    sorted, as ``ndimage.label`` on the bounding image would give them.
    """
    sq = sorted(squares)
    index = {s: k for k, s in enumerate(sq)}
    parent = list(range(len(sq)))

    def find(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for k, (ix, iy) in enumerate(sq):
        for a, b in _NEIGHBOURS:
            j = index.get((ix + a, iy + b))
            if j is not None:
                rk, rj = find(k), find(j)
                if rk != rj:
                    parent[max(rk, rj)] = min(rk, rj)
    groups: dict[int, list[tuple[int, int]]] = {}
    for k, s in enumerate(sq):
        groups.setdefault(find(k), []).append(s)
    return list(groups.values())


def find_vertices(
    classify: Callable[[np.ndarray], np.ndarray],
    x_range: tuple[float, float],
    y_range: tuple[float, float],
    res: int | tuple[int, int],
    *,
    tol: float = 1e-9,
    max_depth: int | None = None,
    min_labels: int = 3,
    samples_per_side: int = 2,
    max_squares: int = 256,
    exclude: Iterable[Hashable] = (),
) -> pd.DataFrame:
    """Locate points where three or more labels meet, by recursive refinement.

    The window is covered by ``(nx - 1) x (ny - 1)`` squares between the
    nodes of an ``nx x ny`` grid. Each square is sampled on a lattice of
    ``samples_per_side`` intervals per side, padded by one lattice step all
    round (``(m + 3)**2`` points for ``m = samples_per_side``); a square is a
    *candidate* when its samples carry at least ``min_labels`` distinct labels.
    Adjacent candidates of the starting grid form one *root*. Every candidate
    is split into its four children, which are sampled the same way with new
    calls of ``classify`` (evaluations are cached and batched per level), until
    the squares are smaller than ``tol``.

    Parameters
    ----------
    classify : callable
        ``classify(points (n, 2)) -> labels (n,)``, slice coordinates.
    x_range, y_range : (float, float)
        Window, slice units.
    res : int or (int, int)
        Starting grid nodes per axis (``nx, ny``). The first level costs
        ``(m (nx - 1) + 1) (m (ny - 1) + 1)`` evaluations.
    tol : float, optional
        Stop when both sides of the squares are below ``tol`` (slice units).
    max_depth : int, optional
        Number of halvings; default enough to reach ``tol`` (at most 60).
    min_labels : int, optional
        Distinct labels that make a candidate (default 3: a triple point).
    samples_per_side : int, optional
        ``m`` above (default 2).
    max_squares : int, optional
        A root whose candidates exceed this number at one level is given up as
        ``"unresolved"`` (e.g. a fractal boundary where the labels meet
        everywhere).
    exclude : iterable, optional
        Labels that do not count (e.g. ``(-1,)`` for "did not settle").

    Returns
    -------
    pandas.DataFrame
        One row per vertex or lost candidate, columns:

        ``root`` (int), ``status``: ``"vertex"`` (squares smaller than
        ``tol`` still carry ``min_labels`` labels; ``x, y`` is the centre of
        the cluster of those squares), ``"split"`` (no child of the last
        candidates carries ``min_labels`` labels: the labels do not meet at one
        point at this scale; ``x, y, size_*`` describe the last candidates),
        ``"unresolved"`` (``max_squares`` exceeded) or ``"max_depth"``;
        ``size_x, size_y`` (extent of the cluster, slice units), ``depth``
        (halvings), ``labels`` (tuple of the labels seen), ``n_squares``.
        ``DataFrame.attrs["n_evals"]`` holds the number of points classified.

    Notes
    -----
    A label region thinner than the sampling lattice can be missed at the
    first level; refine the starting grid when a vertex is expected but not
    found. Padding keeps a vertex that sits on a square's edge.
    """
    nx, ny = (int(res), int(res)) if np.isscalar(res) else (int(res[0]), int(res[1]))
    if nx < 2 or ny < 2:
        raise ValueError("res must be at least 2 per axis")
    m = int(samples_per_side)
    if m < 1:
        raise ValueError("samples_per_side must be >= 1")
    x0, x1 = map(float, x_range)
    y0, y1 = map(float, y_range)
    hx0, hy0 = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    if max_depth is None:
        max_depth = max(0, math.ceil(math.log2(max(hx0, hy0) / tol)) + 1)
    D = int(min(max_depth, 60))
    ux, uy = hx0 / (m * 2.0**D), hy0 / (m * 2.0**D)  # global lattice unit
    Xmax, Ymax = (nx - 1) * m * 2**D, (ny - 1) * m * 2**D
    excl = set(exclude)
    cache: dict[tuple[int, int], object] = {}
    n_evals = 0

    def ensure(keys) -> None:
        nonlocal n_evals
        missing = [k for k in dict.fromkeys(keys) if k not in cache]
        if not missing:
            return
        K = np.array(missing, dtype=np.float64)
        pts = np.column_stack([x0 + K[:, 0] * ux, y0 + K[:, 1] * uy])
        labs = np.asarray(classify(pts)).ravel()
        n_evals += len(missing)
        for k, v in zip(missing, labs):
            cache[k] = _hashable(v)

    def sample_keys(ix: int, iy: int, level: int) -> list[tuple[int, int]]:
        step = 2 ** (D - level)
        keys = []
        for a in range(-1, m + 2):
            X = (ix * m + a) * step
            if X < 0 or X > Xmax:
                continue
            for b in range(-1, m + 2):
                Y = (iy * m + b) * step
                if 0 <= Y <= Ymax:
                    keys.append((X, Y))
        return keys

    def labels_of(ix: int, iy: int, level: int) -> set:
        return {cache[k] for k in sample_keys(ix, iy, level)} - excl

    # ---- level 0: the whole lattice in one call
    Lx, Ly = m * (nx - 1) + 1, m * (ny - 1) + 1
    step0 = 2**D
    gi, gj = np.meshgrid(np.arange(Lx), np.arange(Ly), indexing="ij")
    pts = np.column_stack([x0 + (gi.ravel() * step0) * ux, y0 + (gj.ravel() * step0) * uy])
    lab0 = np.asarray(classify(pts)).ravel()
    n_evals += len(lab0)
    for a, b, v in zip(gi.ravel().tolist(), gj.ravel().tolist(), lab0.tolist()):
        cache[(a * step0, b * step0)] = v
    lab0 = lab0.reshape(Lx, Ly)
    # distinct labels in each padded window: presence per label, windowed
    count = np.zeros((nx - 1, ny - 1), dtype=np.int64)
    for v in np.unique(lab0):
        if _hashable(v) in excl:
            continue
        ind = (lab0 == v).astype(np.uint8)
        pad = np.pad(ind, 1)
        win = np.lib.stride_tricks.sliding_window_view(pad, (m + 3, m + 3))[::m, ::m]
        count += win[: nx - 1, : ny - 1].any(axis=(2, 3))
    qual0 = count >= min_labels
    root_ids, nroots = ndimage.label(qual0, structure=np.ones((3, 3), dtype=bool))
    active: dict[int, set[tuple[int, int]]] = {}
    for r in range(1, nroots + 1):
        ii, jj = np.nonzero(root_ids == r)
        active[r] = set(zip(ii.tolist(), jj.tolist()))

    rows: list[dict] = []

    def cluster_rows(r: int, squares: set, level: int, status: str) -> None:
        hx, hy = hx0 / 2.0**level, hy0 / 2.0**level
        for members in _clusters(squares):
            labs = set()
            for ix, iy in members:
                labs |= labels_of(ix, iy, level)
            n = len(members)
            xs = [ix for ix, _ in members]
            ys = [iy for _, iy in members]
            # exact integer sums (lattice indices can exceed 2**53 at depth)
            cx = x0 + (sum(xs) / n + 0.5) * hx
            cy = y0 + (sum(ys) / n + 0.5) * hy
            rows.append(
                {
                    "root": r,
                    "status": status,
                    "x": float(cx),
                    "y": float(cy),
                    "size_x": float((max(xs) - min(xs) + 1) * hx),
                    "size_y": float((max(ys) - min(ys) + 1) * hy),
                    "depth": level,
                    "labels": tuple(sorted(labs, key=lambda v: (isinstance(v, str), v))),
                    "n_squares": n,
                }
            )

    level = 0
    done = max(hx0, hy0) < tol
    while active and not done and level < D:
        level += 1
        children = {
            r: {(2 * ix + a, 2 * iy + b) for ix, iy in sq for a in (0, 1) for b in (0, 1)}
            for r, sq in active.items()
        }
        keys = [k for ch in children.values() for c in ch for k in sample_keys(*c, level)]
        ensure(keys)
        nxt: dict[int, set] = {}
        for r, ch in children.items():
            q = {c for c in ch if len(labels_of(*c, level)) >= min_labels}
            if not q:
                cluster_rows(r, active[r], level - 1, "split")
            elif len(q) > max_squares:
                cluster_rows(r, active[r], level - 1, "unresolved")
            else:
                nxt[r] = q
        active = nxt
        done = max(hx0, hy0) / 2.0**level < tol
    for r, sq in active.items():
        cluster_rows(r, sq, level, "vertex" if done else "max_depth")
    out = pd.DataFrame(rows, columns=_COLUMNS)
    out = out.sort_values(["root", "x", "y"]).reset_index(drop=True)
    out.attrs["n_evals"] = n_evals
    return out


class _GuardedNumpy:
    """numpy, except that ``zeros`` refuses arrays above ``limit`` elements (raises MemoryError).

    :func:`find_vertices` draws the squares of each root on a dense boolean image spanning their bounding
    box at the current level; when a root's squares are spread out at a deep level that image needs
    terabytes. This guard turns that into a reported failure instead of exhausting memory.
    """

    def __init__(self, limit: int, real=np):
        self._limit = int(limit)
        self._np = real

    def __getattr__(self, name):
        return getattr(self._np, name)

    def zeros(self, shape, *a, **k):
        if int(self._np.prod(shape, dtype=self._np.float64)) > self._limit:
            raise MemoryError(f"find_vertices asked for a {shape} image")
        return self._np.zeros(shape, *a, **k)


def guarded_find_vertices(*a, limit: int = 50_000_000, **k) -> pd.DataFrame:
    """:func:`find_vertices` (same arguments) refusing, with MemoryError, any image above ``limit`` elements."""
    global np
    real = np
    np = _GuardedNumpy(limit, real)
    try:
        return find_vertices(*a, **k)
    finally:
        np = real


def triple_boxes(g: np.ndarray, b: int) -> int:
    """Number of closed b×b-interval squares of the grid holding ≥ 3 outcomes (1..6)."""
    count = np.zeros(((g.shape[0] - 1) // b, (g.shape[1] - 1) // b), dtype=np.int64)
    for lab in range(1, 7):
        ind = g == lab
        if not ind.any():
            continue
        win = np.lib.stride_tricks.sliding_window_view(ind, (b + 1, b + 1))[::b, ::b]
        count += win[: count.shape[0], : count.shape[1]].any(axis=(2, 3))
    return int((count >= 3).sum())
