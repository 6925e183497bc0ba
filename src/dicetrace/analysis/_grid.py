"""Private helpers shared by the grid analyses (label encoding, boxes)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import ndimage

_CONNECTIVITY = ("face", "full")


def as_label_grid(grid, *, ndim: tuple[int, ...] = (2, 3)) -> np.ndarray:
    arr = np.asarray(grid)
    if arr.ndim not in ndim:
        raise ValueError(f"label grid must have ndim in {ndim}, got shape {arr.shape}")
    if min(arr.shape) < 1:
        raise ValueError(f"empty label grid, shape {arr.shape}")
    return arr


def encode_labels(grid) -> tuple[np.ndarray, list]:
    """Integer codes (same shape) and the label of each code.

    Integer grids keep their values as codes; other grids (e.g. contact-sequence
    strings) are factorised, codes 0..n-1 in sorted label order.
    """
    arr = np.asarray(grid)
    if arr.dtype.kind in "iub":
        codes = arr.astype(np.int64, copy=False)
        uniq = [v.item() for v in np.unique(codes)]
        return codes, uniq
    flat = pd.Series(arr.ravel(), dtype=object)
    codes, uniques = pd.factorize(flat, sort=True)
    return codes.astype(np.int64).reshape(arr.shape), list(uniques)


def structure(ndim: int, connectivity: str) -> np.ndarray:
    if connectivity not in _CONNECTIVITY:
        raise ValueError(f"connectivity must be 'face' or 'full', not {connectivity!r}")
    return ndimage.generate_binary_structure(ndim, 1 if connectivity == "face" else ndim)


def neighbour_offsets(ndim: int, connectivity: str) -> list[tuple[int, ...]]:
    """Half of the neighbour offsets (one of each +-pair)."""
    st = structure(ndim, connectivity)
    offs = []
    for idx in np.argwhere(st):
        off = tuple(int(v) - 1 for v in idx)
        if any(off) and off > tuple(-o for o in off):
            offs.append(off)
    return offs


def shifted_pair(arr: np.ndarray, off: tuple[int, ...]):
    """Views (a, b) with b[p] = arr[p + off] over the overlap, and their slices."""
    sa, sb = [], []
    for o, n in zip(off, arr.shape):
        if o >= 0:
            sa.append(slice(0, n - o))
            sb.append(slice(o, n))
        else:
            sa.append(slice(-o, n))
            sb.append(slice(0, n + o))
    return tuple(sa), tuple(sb)


def boxes(arr: np.ndarray, box_size: int) -> np.ndarray:
    """Non-overlapping boxes of side ``box_size``: shape (nboxes, box_size**ndim).

    Trailing rows/columns that do not fill a whole box are dropped.
    """
    b = int(box_size)
    if b < 1:
        raise ValueError("box_size must be >= 1")
    nb = [n // b for n in arr.shape]
    if min(nb) < 1:
        raise ValueError(f"box_size {b} larger than the grid {arr.shape}")
    a = arr[tuple(slice(0, k * b) for k in nb)]
    shape = []
    for k in nb:
        shape += [k, b]
    a = a.reshape(shape)
    d = arr.ndim
    a = a.transpose([2 * i for i in range(d)] + [2 * i + 1 for i in range(d)])
    return a.reshape(int(np.prod(nb)), b**d)


def closed_box_minmax(codes: np.ndarray, box_size: int) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of the closed boxes of ``box_size`` nodes a side (nodes ``k(b-1) .. k(b-1)+b-1``).

    Neighbouring boxes share their faces (a box of ``b`` nodes spans ``b - 1``
    intervals), so every pair of neighbouring nodes lies in some box: a label
    change between boxes is not missed.  Boxes that would reach past the grid
    are dropped.
    """
    b = int(box_size)
    if b < 2:
        raise ValueError("box_size must be >= 2 nodes (a closed box spans box_size - 1 intervals)")
    if any(n < b for n in codes.shape):
        raise ValueError(f"box_size {b} too large for the grid {codes.shape}")
    win = np.lib.stride_tricks.sliding_window_view(codes, (b,) * codes.ndim)
    win = win[tuple(slice(None, None, b - 1) for _ in range(codes.ndim))]
    axes = tuple(range(codes.ndim, 2 * codes.ndim))
    return win.min(axis=axes), win.max(axis=axes)
