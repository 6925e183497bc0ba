"""``analysis.label_cells`` two ways, side by side: scikit-image's one labelling pass against scipy's ``ndimage.label``.

``label_cells`` numbers the connected cells of every label of a grid (ids label by label, raster order within
a label).  Two implementations give that same answer:

* **skimage**: what ``label_cells`` does, one pass of ``skimage.measure.label`` over all labels at once
  (neighbours of equal value join), then the ids renumbered label by label;
* **scipy**: ``scipy.ndimage.label`` of each label's mask, cut to that label's bounding box
  (``ndimage.find_objects``), the ids offset label after label (no renumbering needed).

Both are run, checked equal, and timed (best of ``--repeat``) on four grids: a 4000×4000 outcome map of 6
labels in blocks of 2–200 nodes a side (a zoomed-out map), the same at 2000² with full (8-neighbour)
connectivity, a 160³ stack of 6 labels, and a 1000×1000 grid of 5000 labels in small blocks (contact
sequences, whose labels are many and scattered).  The ratio scipy / skimage is printed for each: above 1,
scikit-image is the faster and stays the labelling of ``label_cells`` (the ``analysis`` extra).

Usage: ``python benchmarks/bench_cells.py [--n 4000] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import ndimage

from dicetrace.analysis import label_cells
from dicetrace.analysis._grid import structure


def _grid(n: int, rng) -> np.ndarray:
    """Blocks of random sizes (2–200 nodes a side) and random labels 1..6."""
    xs = np.cumsum(rng.integers(2, 200, size=n))
    ys = np.cumsum(rng.integers(2, 200, size=n))
    bx = np.searchsorted(xs, np.arange(n), side="right")
    by = np.searchsorted(ys, np.arange(n), side="right")
    table = rng.integers(1, 7, size=(bx.max() + 1, by.max() + 1))
    g = table[bx[:, None], by[None, :]]
    noise = rng.random((n, n)) < 0.01  # isolated nodes, like border noise
    g[noise] = rng.integers(1, 7, size=int(noise.sum()))
    return g.astype(np.int8)


def _blocks(n: int, k: int, ndim: int, rng) -> np.ndarray:
    """Blocks of 2–30 nodes a side with random labels 1..k, 1 % of the nodes relabelled at random."""
    cuts = [np.searchsorted(np.cumsum(rng.integers(2, 30, size=n)), np.arange(n), side="right") for _ in range(ndim)]
    g = rng.integers(1, k + 1, size=tuple(int(c.max()) + 1 for c in cuts))[np.ix_(*cuts)]
    noise = rng.random(g.shape) < 0.01
    g[noise] = rng.integers(1, k + 1, size=int(noise.sum()))
    return g.astype(np.int32)


def scipy_label_cells(grid: np.ndarray, connectivity: str = "face") -> tuple[np.ndarray, int]:
    """``label_cells`` of a grid of positive integer labels by ``ndimage.label``, label by label in its box."""
    st = structure(grid.ndim, connectivity)
    out = np.zeros(grid.shape, dtype=np.int64)
    n = 0
    for k, box in enumerate(ndimage.find_objects(grid), start=1):
        if box is None:
            continue
        comp, m = ndimage.label(grid[box] == k, structure=st)
        if m:
            sub, inside = out[box], comp > 0
            sub[inside] = comp[inside] + n
            n += m
    return out, n


def best(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=4000, help="side of the 2-D outcome map (the others scale with it)")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    n = args.n
    cases = [
        (f"{n}² outcome map, 6 labels", _grid(n, rng), "face"),
        (f"{n // 2}² outcome map, 6 labels, full", _grid(n // 2, rng), "full"),
        (f"{n // 25}³ stack, 6 labels", _blocks(n // 25, 6, 3, rng), "face"),
        (f"{n // 4}² sequences, 5000 labels", _blocks(n // 4, 5000, 2, rng), "face"),
    ]
    print(f"best of {args.repeat}; ms")
    print(f"{'grid':<36} {'cells':>9} {'skimage':>9} {'scipy':>9}  scipy/skimage")
    for name, g, conn in cases:
        t_sk, (ids, ncells) = best(lambda: label_cells(g, connectivity=conn), args.repeat)
        t_sp, (ids_sp, n_sp) = best(lambda: scipy_label_cells(g.astype(np.int32), conn), args.repeat)
        assert n_sp == ncells and np.array_equal(ids_sp, ids), name  # the same answer
        print(f"{name:<36} {ncells:>9,} {t_sk * 1e3:>9.1f} {t_sp * 1e3:>9.1f}  ×{t_sp / t_sk:.2f}")


if __name__ == "__main__":
    main()
