"""Cells: connected regions of equal label on 2-D and 3-D label grids.

A *cell* (writeup section 4.1) is a connected compartment of initial-condition
space with one outcome. On a sampled grid it is a connected component of grid
nodes that carry the same label, with face (4/6-neighbour) or full
(8/26-neighbour) connectivity. Labels may be integers (outcomes, -1, 0) or any
hashable (contact-sequence strings): they are factorised to integer codes first.

The 3-D functions answer the writeup's question of section 5.1 ("are these
repeating regions different cells, or slices of the same cell?") within a
sampled 3-D stack: two 2-D cells of a slice are the same 3-D cell when they lie
in one 3-D component.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Sequence

import numpy as np
import pandas as pd
from scipy import ndimage

from dicetrace.extras import require

from ._grid import as_label_grid, encode_labels, structure

__all__ = ["label_cells", "cells_table", "same_cell", "slice_cell_components", "block_fraction_stderr", "cell_stats",
           "slice_joins"]


def label_cells(
    grid, *, connectivity: str = "face", exclude: Iterable[Hashable] = ()
) -> tuple[np.ndarray, int]:
    """Connected components of equal label.

    Parameters
    ----------
    grid : array_like, shape (nx, ny) or (nx, ny, nz)
        Label grid (any hashable labels; 0 and -1 are labels of their own).
    connectivity : {"face", "full"}, optional
        ``"face"`` (default): nodes sharing a face (4 neighbours in 2-D, 6 in
        3-D). ``"full"``: also edges and corners (8 / 26 neighbours).
    exclude : iterable, optional
        Labels whose nodes get no cell (cell id 0), e.g. ``(-1,)``.

    Returns
    -------
    cell_ids : numpy.ndarray of int64, same shape as ``grid``
        Cell id of every node, 1..ncells (0 for excluded labels). Ids are
        assigned label by label (sorted labels), in raster order within a label.
    ncells : int
    """
    arr = as_label_grid(grid)
    structure(arr.ndim, connectivity)  # validates ``connectivity``
    excl = list(exclude)
    if arr.dtype.kind in "iub":  # the labels are their own codes: no factorisation (a sort) needed
        codes = arr.astype(np.int64, copy=False)
        valid = ~np.isin(codes, np.array([e for e in excl if isinstance(e, (int, np.integer))], dtype=np.int64))
    else:  # factorised; a missing value (code -1) gets no cell
        codes, uniques = encode_labels(arr)
        excl_set = set(excl)
        excl_codes = [i for i, lab in enumerate(uniques) if lab in excl_set]
        valid = (codes >= 0) & ~np.isin(codes, excl_codes)
    if not valid.any():
        return np.zeros(arr.shape, dtype=np.int64), 0
    # one pass of scikit-image's labelling (the analysis extra; faster than scipy's ndimage.label label by label:
    # benchmarks/bench_cells.py): neighbours of equal value join; the background value (0 after the shift) marks
    # the nodes without a cell
    require("analysis", "analysis.label_cells")
    from skimage import measure  # the analysis extra: imported where it labels

    lo, hi = int(codes.min()), int(codes.max())
    vals = (codes - lo + 1).astype(np.int32 if hi - lo < 2**31 - 2 else np.int64)  # int32: a faster labelling
    vals[~valid] = 0
    comp = measure.label(vals, background=0, connectivity=1 if connectivity == "face" else arr.ndim)
    n = int(comp.max())
    # renumber label by label (sorted codes = sorted labels), in raster order
    # within a label: skimage numbers components in raster order of their first
    # node, so a stable sort by label keeps that order
    comp_code = np.zeros(n + 1, dtype=np.int64)
    comp_code[comp.ravel()] = vals.ravel()
    order = np.argsort(comp_code[1:], kind="stable")
    rank = np.zeros(n + 1, dtype=np.int64)
    rank[order + 1] = np.arange(1, n + 1, dtype=np.int64)
    return rank[comp], n


def _to_slice_units(centroid: np.ndarray, shape, extent) -> np.ndarray:
    ext = np.asarray(extent, dtype=float)
    if ext.shape != (len(shape), 2):
        raise ValueError(f"extent must be {len(shape)} (lo, hi) pairs, got {extent!r}")
    n = np.asarray(shape, dtype=float)
    scale = np.where(n > 1, (ext[:, 1] - ext[:, 0]) / np.maximum(n - 1, 1), 0.0)
    return ext[:, 0] + centroid * scale


def cells_table(
    grid,
    *,
    connectivity: str = "face",
    extent: Sequence[tuple[float, float]] | None = None,
    exclude: Iterable[Hashable] = (),
) -> pd.DataFrame:
    """One row per cell of a 2-D or 3-D label grid.

    Parameters
    ----------
    grid : array_like, shape (nx, ny) or (nx, ny, nz)
        Label grid.
    connectivity : {"face", "full"}, optional
        See :func:`label_cells`.
    extent : sequence of (lo, hi), optional
        Slice coordinates of the first and last node along each axis, e.g.
        ``[(x0, x1), (y0, y1)]``; adds a ``centroid_slice`` column.
    exclude : iterable, optional
        Labels that form no cells.

    Returns
    -------
    pandas.DataFrame
        Columns ``cell_id`` (int64, as in :func:`label_cells`), ``label``,
        ``size`` (number of nodes), ``bbox`` (tuple of inclusive
        ``(lo, hi)`` index pairs per axis), ``centroid`` (tuple of mean grid
        indices), ``touches_edge`` (bool: the cell reaches the grid's border,
        so it may continue outside the window) and, with ``extent``,
        ``centroid_slice`` (tuple, slice units).
    """
    arr = as_label_grid(grid)
    cell_ids, n = label_cells(arr, connectivity=connectivity, exclude=exclude)
    flat = cell_ids.ravel()
    sizes = np.bincount(flat, minlength=n + 1)[1:]
    ids_present, first = np.unique(flat, return_index=True)
    first_of = dict(zip(ids_present.tolist(), first.tolist()))
    labels_flat = arr.ravel()
    labels = [labels_flat[first_of[c]] for c in range(1, n + 1)]
    labels = [v.item() if isinstance(v, np.generic) else v for v in labels]
    idx = np.indices(arr.shape).reshape(arr.ndim, -1)
    cent = np.stack(
        [np.bincount(flat, weights=idx[a], minlength=n + 1)[1:] for a in range(arr.ndim)], axis=1
    ) / np.maximum(sizes, 1)[:, None]
    objs = ndimage.find_objects(cell_ids, max_label=n)
    bboxes, touches = [], []
    for sl in objs:
        bb = tuple((s.start, s.stop - 1) for s in sl)
        bboxes.append(bb)
        touches.append(any(lo == 0 or hi == m - 1 for (lo, hi), m in zip(bb, arr.shape)))
    all_int = all(isinstance(v, (int, np.integer)) for v in labels)
    out = pd.DataFrame(
        {
            "cell_id": np.arange(1, n + 1, dtype=np.int64),
            "label": pd.Series(labels, dtype=np.int64 if (all_int and n) else object),
            "size": sizes.astype(np.int64),
            "bbox": pd.Series(bboxes, dtype=object),
            "centroid": pd.Series([tuple(c) for c in cent], dtype=object),
            "touches_edge": np.array(touches, dtype=bool),
        }
    )
    if extent is not None:
        cs = _to_slice_units(cent, arr.shape, extent) if n else np.zeros((0, arr.ndim))
        out["centroid_slice"] = pd.Series([tuple(c) for c in cs], dtype=object)
    return out


def same_cell(
    grid3d,
    a: Sequence[int],
    b: Sequence[int],
    *,
    connectivity: str = "face",
    cell_ids: np.ndarray | None = None,
) -> bool:
    """Whether two grid nodes lie in one connected cell of the 3-D grid.

    Parameters
    ----------
    grid3d : array_like, shape (nx, ny, nz)
        Label grid of a 3-D slice stack (2-D grids work as well).
    a, b : sequence of int
        Node indices ``(i, j, k)``.
    connectivity : {"face", "full"}, optional
        See :func:`label_cells`.
    cell_ids : numpy.ndarray, optional
        Output of ``label_cells(grid3d, connectivity=...)[0]``, to reuse across
        many queries.

    Returns
    -------
    bool
        ``True`` when the nodes carry the same label and are connected through
        nodes of that label inside the sampled stack. ``False`` can still mean
        "connected outside the sampled window or between its samples".
    """
    arr = as_label_grid(grid3d)
    if cell_ids is None:
        cell_ids, _ = label_cells(arr, connectivity=connectivity)
    a, b = tuple(int(v) for v in a), tuple(int(v) for v in b)
    if len(a) != arr.ndim or len(b) != arr.ndim:
        raise ValueError(f"indices must have {arr.ndim} components")
    ca, cb = cell_ids[a], cell_ids[b]
    return bool(ca != 0 and ca == cb)


def slice_cell_components(
    grid3d, k: int, *, axis: int = 2, connectivity: str = "face"
) -> pd.DataFrame:
    """3-D component of every 2-D cell of one slice of a 3-D stack.

    Parameters
    ----------
    grid3d : array_like, shape (nx, ny, nz)
        Label grid.
    k : int
        Slice index along ``axis``.
    axis : int, optional
        The stacking axis, default 2 (the slice's third coordinate z).
    connectivity : {"face", "full"}, optional
        Used in 2-D (4/8 neighbours) and in 3-D (6/26 neighbours) alike.

    Returns
    -------
    pandas.DataFrame
        The :func:`cells_table` of the slice (``cell_id`` are 2-D ids in the
        slice) plus ``component_3d`` (3-D cell id, as in :func:`label_cells` on
        the stack) and ``n_cells_in_component`` (how many 2-D cells of this
        slice share that 3-D component: > 1 means "several regions in the
        picture, one cell in the stack").
    """
    arr = as_label_grid(grid3d, ndim=(3,))
    ids3, _ = label_cells(arr, connectivity=connectivity)
    sl2 = np.take(arr, k, axis=axis)
    ids3_sl = np.take(ids3, k, axis=axis)
    table = cells_table(sl2, connectivity=connectivity)
    ids2, _ = label_cells(sl2, connectivity=connectivity)
    flat2 = ids2.ravel()
    _, first = np.unique(flat2, return_index=True)
    comp = ids3_sl.ravel()[first]  # ids2 has no zeros (nothing excluded)
    table["component_3d"] = comp.astype(np.int64)
    table["n_cells_in_component"] = table.groupby("component_3d")["cell_id"].transform("size")
    return table


def block_fraction_stderr(grid: np.ndarray, label: int, n_blocks: int = 4) -> float:
    """Stderr of a basin fraction from its spread over n_blocks² sub-grids."""
    nx, ny = grid.shape
    ex = np.linspace(0, nx, n_blocks + 1).astype(int)
    ey = np.linspace(0, ny, n_blocks + 1).astype(int)
    vals = [np.mean(grid[ex[a]:ex[a + 1], ey[b]:ey[b + 1]] == label) for a in range(n_blocks) for b in range(n_blocks)]
    return float(np.std(vals, ddof=1) / np.sqrt(len(vals)))


def cell_stats(grid: np.ndarray) -> dict:
    """Statistics of the cells of a 2-D outcome map (face connectivity): how many, their sizes (``sizes``: every
    cell's node count), singletons, the largest, and the share of nodes in cells that touch the map's edge."""
    t = cells_table(grid, connectivity="face")
    sizes = t["size"].to_numpy()
    n = grid.size
    return {
        "n_cells": int(len(t)),
        "n_nodes": int(n),
        "cells_per_1000_nodes": 1000.0 * len(t) / n,
        "n_singletons": int((sizes == 1).sum()),
        "frac_nodes_in_singletons": float(sizes[sizes == 1].sum() / n),
        "n_cells_ge_10": int((sizes >= 10).sum()),
        "n_cells_ge_100": int((sizes >= 100).sum()),
        "largest_cell_frac": float(sizes.max() / n),
        "largest_cell_label": int(t.loc[t["size"].idxmax(), "label"]),
        "median_size": float(np.median(sizes)),
        "mean_size": float(sizes.mean()),
        "frac_nodes_in_edge_cells": float(sizes[t["touches_edge"].to_numpy()].sum() / n),
        "sizes": sizes,
    }


def slice_joins(g: np.ndarray, min_cell: int) -> dict:
    """How many 2-D cells of slice z = 0 of the 3-D stack ``g`` share a 3-D component with another 2-D cell of that
    slice (cells of at least ``min_cell`` nodes), in all and per label; with ``half_res``, the same at half the
    resolution in all three axes (is the answer resolution-dependent?) when every axis has 9 nodes or more."""
    t = slice_cell_components(g, 0)
    big = t[t["size"] >= min_cell]
    joined = big[big["n_cells_in_component"] > 1]
    z0 = {
        "n_cells_2d": int(len(t)), f"n_cells_2d_ge{min_cell}": int(len(big)),
        "n_components_3d_of_those": int(big["component_3d"].nunique()),
        "frac_cells_joined": float(len(joined) / max(len(big), 1)),
        "frac_area_joined": float(joined["size"].sum() / max(big["size"].sum(), 1)),
        "per_label": [{"label": int(lab), "cells_2d": int(len(grp)), "components_3d": int(grp["component_3d"].nunique())}
                      for lab, grp in big.groupby("label")],
    }
    # the same at half the resolution in all three axes (is the answer resolution-dependent?)
    if min(g.shape) >= 9:
        g2 = g[::2, ::2, ::2]
        t2 = slice_cell_components(g2, 0)
        b2 = t2[t2["size"] >= max(2, min_cell // 4)]
        z0["half_res"] = {
            "res": g2.shape, "n_cells_2d_big": int(len(b2)),
            "n_components_3d_of_those": int(b2["component_3d"].nunique()),
            "frac_cells_joined": float((b2["n_cells_in_component"] > 1).sum() / max(len(b2), 1)),
        }
    return z0
