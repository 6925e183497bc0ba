"""One cell or many? The shift-overlap against a null model, and the 3-D join fraction across resolutions.

Two measures of whether regions of one outcome that repeat in a 2-D slice
are one cell of the 6-D space:

* :func:`shift_overlap_test`: the cells of a map are shifted by a candidate
  period; the *overlap* of a cell is the fraction of its shifted nodes that
  land in its best same-outcome partner cell (median over cells ≥
  ``min_size`` nodes).  A high overlap alone means nothing when cells are
  large or one outcome dominates, so it is compared with a null model: the
  same statistic at ``n_null`` shifts of the same length in random
  directions (the map's own cell sizes and face fractions, no period).  The
  one-sided p-value is the fraction of null shifts with an overlap at least
  as high (with the +1 correction of a permutation test).
* :func:`join_fraction`: in a 3-D stack (a slice thickened along a third IC
  direction) the fraction of the 2-D cells of one slice (≥ ``min_cell``
  nodes) that share a 3-D connected cell with another 2-D cell of that
  slice.  It can only grow as the stack is refined (thin connections
  appear), so a value is an answer only when it has stopped changing over a
  resolution series; otherwise it is undetermined
  (:func:`resolution_verdict`).  :func:`join_counts` gives the counts behind
  it, with the cells chosen by a fixed share of the slice's area (so that a
  resolution series compares the same cells, not ever smaller ones).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._grid import as_label_grid
from .cells import cells_table, slice_cell_components
from .repetition import periodic_cells_connected

__all__ = ["ShiftOverlapTest", "shift_overlap", "shift_overlap_test", "join_fraction", "join_counts", "min_cell_nodes",
           "resolution_verdict"]


def shift_overlap(grid, shift, *, min_size: int = 20) -> float:
    """Median overlap of the cells (≥ ``min_size`` nodes) of a 2-D map shifted by ``shift`` (grid nodes)."""
    g = as_label_grid(grid, ndim=(2,))
    pc = periodic_cells_connected(g[:, :, None], (int(shift[0]), int(shift[1])), k=0)
    if pc.empty:
        return math.nan
    sizes = cells_table(g).set_index("cell_id")["size"]
    size = sizes.reindex(pc["cell_id"]).to_numpy()
    big = pc[size >= min_size]
    return float(big["overlap"].median()) if len(big) else math.nan


@dataclasses.dataclass(frozen=True)
class ShiftOverlapTest:
    """The overlap at the candidate shift, the null overlaps, and the one-sided p-value."""

    overlap: float
    null: np.ndarray
    p_value: float
    null_median: float


def shift_overlap_test(grid, shift, *, n_null: int = 99, min_size: int = 20, exclude_deg: float = 10.0,
                       rng: np.random.Generator | int = 0) -> ShiftOverlapTest:
    """:func:`shift_overlap` at ``shift`` against shifts of the same length in random directions.

    Directions within ``exclude_deg`` of ``±shift`` are not drawn (``−shift`` is a period whenever ``shift``
    is one).
    """
    g = as_label_grid(grid, ndim=(2,))
    gen = np.random.default_rng(rng)
    obs = shift_overlap(g, shift, min_size=min_size)
    length = math.hypot(*shift)
    null = []
    a0 = math.atan2(shift[1], shift[0])
    while len(null) < int(n_null):
        a = gen.uniform(0, 2 * math.pi)
        off = abs((a - a0 + math.pi / 2) % math.pi - math.pi / 2)  # angle to the line of ±shift
        if off < math.radians(exclude_deg):
            continue
        s = (int(round(length * math.cos(a))), int(round(length * math.sin(a))))
        null.append(shift_overlap(g, s, min_size=min_size))
    null = np.asarray(null, dtype=float)
    ok = null[np.isfinite(null)]
    p = (1 + int((ok >= obs).sum())) / (1 + len(ok)) if math.isfinite(obs) and len(ok) else math.nan
    return ShiftOverlapTest(obs, null, float(p), float(np.median(ok)) if len(ok) else math.nan)


def join_fraction(grid3d, *, k: int = 0, min_cell: int = 5) -> float:
    """Fraction of the 2-D cells (≥ ``min_cell`` nodes) of slice ``k`` of a stack joined to another through 3-D."""
    t = slice_cell_components(as_label_grid(grid3d, ndim=(3,)), k)
    big = t[t["size"] >= min_cell]
    if big.empty:
        return math.nan
    return float((big["n_cells_in_component"] > 1).mean())


def min_cell_nodes(nx: int, ny: int, min_area: float) -> int:
    """Nodes of a 2-D cell of at least ``min_area`` (a share of the slice) on an ``nx × ny`` grid (at least 2)."""
    return max(2, int(math.ceil(float(min_area) * nx * ny)))


def join_counts(grid3d, *, k: int = 0, min_area: float = 0.01) -> dict:
    """The 2-D cells of slice ``k`` of a stack covering at least ``min_area`` of the slice, and how many of them share
    a 3-D cell with another 2-D cell of that slice.

    Returns ``n_cells`` (those cells), ``n_joined``, ``fraction`` (``n_joined / n_cells``, NaN without cells), its
    binomial ``stderr``, ``area_fraction`` (the joined cells' share of those cells' nodes), ``n_components`` (the 3-D
    cells they belong to), ``min_cell`` (nodes) and ``n_cells_2d`` (every 2-D cell of the slice).
    """
    g = as_label_grid(grid3d, ndim=(3,))
    t = slice_cell_components(g, k)
    m = min_cell_nodes(g.shape[0], g.shape[1], min_area)
    big = t[t["size"] >= m]
    joined = big[big["n_cells_in_component"] > 1]
    n = int(len(big))
    f = len(joined) / n if n else math.nan
    return {"n_cells": n, "n_joined": int(len(joined)), "fraction": float(f),
            "stderr": float(math.sqrt(f * (1 - f) / n)) if n else math.nan,
            "area_fraction": float(joined["size"].sum() / big["size"].sum()) if n else math.nan,
            "n_components": int(big["component_3d"].nunique()), "min_cell": int(m), "n_cells_2d": int(len(t))}


def resolution_verdict(values, counts, *, z: float = 2.0) -> str:
    """``"converged"`` when a resolution series (coarse to fine) has stopped moving, else ``"undetermined"``.

    ``values`` are fractions of ``counts`` cells.  Converged: the last value
    agrees with each of the two before it within ``z`` binomial standard
    errors of the difference (a slow drift over the last three is not a
    converged value).
    """
    v = np.asarray(values, dtype=float)
    n = np.asarray(counts, dtype=float)
    if len(v) < 3 or not np.all(np.isfinite(v[-3:])):
        return "undetermined"

    def se(i: int, j: int) -> float:
        return math.sqrt(v[i] * (1 - v[i]) / max(n[i], 1) + v[j] * (1 - v[j]) / max(n[j], 1))

    ok = all(abs(v[-1] - v[i]) <= z * max(se(-1, i), 1e-12) for i in (-2, -3))
    return "converged" if ok else "undetermined"
