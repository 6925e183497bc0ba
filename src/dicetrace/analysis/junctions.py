"""Where three cells meet: box counts of triple junctions, their dimension, and maps with a known answer.

The writeup's vertex hunt asks whether three cells meet at isolated points
(vertices) of a 2-D slice.  Counting the boxes of side ``b`` that hold three
outcomes or more, ``N(b)``, answers it by the growth of ``N`` as ``b``
shrinks: ``N(b) ~ b**-D`` with ``D = 0`` for isolated vertices (the count
stays put), ``D = 1`` when three outcomes meet along curves, up to 2.

Two counts are kept apart (:func:`junction_box_counts`):

* ``any3``: boxes holding at least three distinct outcomes.  A box that
  crosses two *parallel* borders (a thin strip of a third outcome between
  two others) is counted although no three cells meet in it;
* ``meet3``: boxes in which three outcomes *meet*: three labels every two of
  which are neighbours (grid nodes one step apart, both in the box).  A strip
  A|B|C has the pairs A–B and B–C but not A–C, so it is not counted; a
  triple point has all three pairs.

Counts are averaged over shifted tilings (the box grid moved by a fraction
of a box), which removes the 1-to-4 jitter of an isolated point on an
aligned tiling.  :func:`junction_dimension` fits ``D`` on the scales with
enough boxes, and never returns a negative dimension: a fitted slope that
makes ``N`` grow with ``b`` is reported as ``D = 0`` with the flag
``clamped`` (a count cannot shrink with finer boxes around a set of
dimension ≥ 0 except by noise).

:func:`three_sector_map` (a known triple point) and :func:`strip_map`
(three outcomes, two parallel borders, no vertex) are the method's positive
and negative controls.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

from ._grid import as_label_grid
from .boundaries import fit_power_law

__all__ = ["JunctionCounts", "JunctionDimension", "junction_box_counts", "junction_dimension", "three_sector_map",
           "strip_map", "junction_row"]


@dataclasses.dataclass(frozen=True)
class JunctionCounts:
    """Box counts of one label grid.

    ``box_sizes`` (grid intervals), ``any3`` and ``meet3`` (mean count over the
    tilings), ``n_boxes`` (boxes per tiling), ``centres_meet3`` (slice-index
    centres of the ``meet3`` boxes of the smallest size, unshifted tiling).
    """

    box_sizes: np.ndarray
    any3: np.ndarray
    meet3: np.ndarray
    n_boxes: np.ndarray
    centres_meet3: np.ndarray


@dataclasses.dataclass(frozen=True)
class JunctionDimension:
    """``N(b) ~ b**-D`` fitted on ``used`` scales: ``dimension`` ≥ 0, ``slope_stderr``, ``clamped``."""

    dimension: float
    stderr: float
    clamped: bool
    slope: float
    used: np.ndarray
    n_scales: int


def _box_any(mask: np.ndarray, b: int, ox: int, oy: int, nbx: int, nby: int) -> np.ndarray:
    """Whether each closed box (b + 1 nodes a side, stride b, origin (ox, oy)) holds a True node."""
    sub = mask[ox: ox + nbx * b + 1, oy: oy + nby * b + 1]
    win = np.lib.stride_tricks.sliding_window_view(sub, (b + 1, b + 1))[::b, ::b]
    return win[:nbx, :nby].any(axis=(2, 3))


def _box_edge(edge: np.ndarray, b: int, ox: int, oy: int, nbx: int, nby: int, axis: int) -> np.ndarray:
    """Whether each closed box holds an edge of ``edge`` (edges along ``axis`` between nodes one step apart)."""
    if axis == 0:  # edge[i, j]: nodes (i, j)-(i+1, j); i in [x, x + b - 1], j in [y, y + b]
        sub = edge[ox: ox + nbx * b, oy: oy + nby * b + 1]
        win = np.lib.stride_tricks.sliding_window_view(sub, (b, b + 1))[::b, ::b]
    else:
        sub = edge[ox: ox + nbx * b + 1, oy: oy + nby * b]
        win = np.lib.stride_tricks.sliding_window_view(sub, (b + 1, b))[::b, ::b]
    return win[:nbx, :nby].any(axis=(2, 3))


def junction_box_counts(grid, box_sizes=None, *, exclude=(-1, 0), n_shifts: int = 4,
                        rng: int | None = 0) -> JunctionCounts:
    """Boxes holding three outcomes (``any3``) and boxes where three outcomes meet (``meet3``).

    Parameters
    ----------
    grid : 2-D array of labels
    box_sizes : sequence of int, optional
        Box sides in grid intervals; default the powers of 2 up to an eighth
        of the shorter side (at least 64 boxes per tiling).
    exclude : labels that do not count (default: undefined 0 and unsettled −1).
    n_shifts : tilings per size (the unshifted one and ``n_shifts − 1`` random
        origins within one box), averaged.
    """
    g = as_label_grid(grid, ndim=(2,))
    nx, ny = g.shape
    if box_sizes is None:
        top = max(1, (min(nx, ny) - 1) // 8)
        box_sizes = [2**k for k in range(int(math.log2(top)) + 1)]
    sizes = np.asarray(sorted({int(b) for b in box_sizes}), dtype=np.int64)
    if sizes.size == 0 or sizes[0] < 1:
        raise ValueError("box sizes must be positive integers")
    labs = [v for v in np.unique(g).tolist() if v not in set(exclude)]
    masks = {v: g == v for v in labs}
    pairs = {}
    for p, q in itertools.combinations(labs, 2):
        h = (masks[p][:-1] & masks[q][1:]) | (masks[q][:-1] & masks[p][1:])
        v = (masks[p][:, :-1] & masks[q][:, 1:]) | (masks[q][:, :-1] & masks[p][:, 1:])
        if h.any() or v.any():
            pairs[(p, q)] = (h, v)
    gen = np.random.default_rng(rng)
    any3, meet3, nbox = [], [], []
    centres = np.zeros((0, 2))
    for b in sizes:
        nbx, nby = (nx - 1) // b, (ny - 1) // b
        if nbx < 1 or nby < 1:
            raise ValueError(f"box size {b} exceeds the grid {g.shape}")
        shifts = [(0, 0)] + [(int(gen.integers(0, b)), int(gen.integers(0, b))) for _ in range(max(0, n_shifts - 1))]
        a_counts, m_counts = [], []
        for ox, oy in shifts:
            bx, by = (nx - 1 - ox) // b, (ny - 1 - oy) // b
            if bx < 1 or by < 1:
                continue
            present = np.zeros((bx, by), dtype=np.int64)
            for v in labs:
                present += _box_any(masks[v], b, ox, oy, bx, by)
            a_counts.append(int((present >= 3).sum()))
            has = {k: _box_edge(h, b, ox, oy, bx, by, 0) | _box_edge(v, b, ox, oy, bx, by, 1)
                   for k, (h, v) in pairs.items()}
            meet = np.zeros((bx, by), dtype=bool)
            for p, q, r in itertools.combinations(labs, 3):
                if (p, q) in has and (p, r) in has and (q, r) in has:
                    meet |= has[(p, q)] & has[(p, r)] & has[(q, r)]
            m_counts.append(int(meet.sum()))
            if b == sizes[0] and (ox, oy) == (0, 0):
                ii, jj = np.nonzero(meet)
                centres = np.column_stack([ii * b + b / 2, jj * b + b / 2]).astype(float)
        any3.append(float(np.mean(a_counts)))
        meet3.append(float(np.mean(m_counts)))
        nbox.append(nbx * nby)
    return JunctionCounts(sizes, np.array(any3), np.array(meet3), np.array(nbox, dtype=np.int64), centres)


def junction_dimension(box_sizes, counts, *, min_count: float = 1.0) -> JunctionDimension:
    """``D`` of ``N(b) ~ b**-D`` over the scales where ``N ≥ min_count``; clamped at 0 (``clamped``).

    With fewer than two usable scales (no junctions at all) the dimension is
    ``nan``: there is nothing to measure.
    """
    b = np.asarray(box_sizes, dtype=float)
    n = np.asarray(counts, dtype=float)
    used = n >= min_count
    if used.sum() < 2:
        return JunctionDimension(math.nan, math.nan, False, math.nan, used, int(used.sum()))
    fit = fit_power_law(b[used], n[used])
    d = -fit.slope
    return JunctionDimension(max(d, 0.0) + 0.0, fit.slope_stderr, d < 0, fit.slope, used, int(used.sum()))


def three_sector_map(res: int, *, centre=(0.5 + 1 / (2 * math.pi), 0.5 - 1 / (3 * math.e)),
                     angles=(0.2, 2.3, 4.1), labels=(1, 2, 3)) -> np.ndarray:
    """Labels on a ``res × res`` grid of [0, 1]²: three sectors meeting at ``centre`` (one triple point)."""
    ax = np.linspace(0.0, 1.0, int(res))
    x, y = np.meshgrid(ax, ax, indexing="ij")
    phi = np.mod(np.arctan2(y - centre[1], x - centre[0]) - angles[0], 2 * np.pi)
    edges = np.mod(np.asarray(angles) - angles[0], 2 * np.pi)
    q = np.searchsorted(edges, phi, side="right") - 1
    return np.asarray(labels)[q]


def strip_map(res: int, *, width: float = 0.02, tilt: float = 0.3, labels=(1, 2, 3)) -> np.ndarray:
    """Labels on a ``res × res`` grid of [0, 1]²: a strip of ``labels[1]`` of ``width`` between two others.

    Three outcomes, two parallel (tilted) borders and no point where three
    cells meet: boxes wider than the strip hold three outcomes, none holds a
    triple junction.
    """
    ax = np.linspace(0.0, 1.0, int(res))
    x, y = np.meshgrid(ax, ax, indexing="ij")
    s = (x - 0.5) * math.cos(tilt) + (y - 0.5) * math.sin(tilt)
    return np.where(s < 0, labels[0], np.where(s < width, labels[1], labels[2]))


def junction_row(name: str, grid, **extra) -> dict:
    """The junction measures of one map ``grid`` named ``name`` (with ``extra`` columns): box counts of boxes where
    three outcomes meet (``meet3``) or are present (``any3``), and the dimension of each."""
    c = junction_box_counts(grid)
    dm = junction_dimension(c.box_sizes, c.meet3)
    da = junction_dimension(c.box_sizes, c.any3)
    return {"map": name, **extra, "res": int(grid.shape[0]), "box_sizes": c.box_sizes, "any3": c.any3,
            "meet3": c.meet3, "dim_meet3": dm.dimension, "dim_meet3_stderr": dm.stderr, "clamped": dm.clamped,
            "scales_used": dm.n_scales, "dim_any3": da.dimension, "dim_any3_stderr": da.stderr,
            "n_vertex_boxes_smallest": int(len(c.centres_meet3))}
