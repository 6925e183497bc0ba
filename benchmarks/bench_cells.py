"""Speed of ``analysis.label_cells`` against ``scipy.ndimage.label`` on a large label grid.

A 4000×4000 grid of 6 outcome labels in cells of a few to a few hundred
nodes (blocks of random size and label, like a zoomed-out outcome map).
Prints, best of ``--repeat`` runs:

* ``scipy.ndimage.label`` once per label: the same answer (cells of every
  label) by the plain library route, the reference,
* ``label_cells`` (all labels in one pass of scikit-image's labelling, ids
  renumbered label by label),
* ``ndimage.label`` of a single binary mask (one pass, no labels), for context,

and the ratio of ``label_cells`` to the reference (target: at most 1.5).

Usage: ``python benchmarks/bench_cells.py [--n 4000] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import ndimage

from dicetrace.analysis import label_cells


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


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=4000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    g = _grid(args.n, np.random.default_rng(0))
    mask = g == 1
    t_nd = best(lambda: ndimage.label(mask), args.repeat)
    ids, ncells = label_cells(g)
    t_lc = best(lambda: label_cells(g), args.repeat)
    t_per = best(lambda: [ndimage.label(g == v) for v in range(1, 7)], args.repeat)
    print(f"{args.n}×{args.n} grid, 6 labels, {ncells:,} cells; best of {args.repeat}")
    print(f"ndimage.label once per label (same answer) {t_per * 1e3:8.1f} ms")
    print(f"label_cells, all labels                    {t_lc * 1e3:8.1f} ms   ratio to the reference ×{t_lc / t_per:.2f}")
    print(f"ndimage.label of one binary mask           {t_nd * 1e3:8.1f} ms   (one pass, for context)")


if __name__ == "__main__":
    main()
