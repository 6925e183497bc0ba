"""Face fractions of an outcome map with moving-block bootstrap errors.

The nodes of an outcome map are not independent throws: neighbouring nodes
fall in the same cell, so a binomial error (or a χ² test of the counts)
treats a map of a few large cells as if it held thousands of independent
outcomes and understates the error many times over.  The moving-block
bootstrap (Künsch 1989, Ann. Statist. 17:1217; in two dimensions, Lahiri,
*Resampling Methods for Dependent Data*, 2003, ch. 12) keeps the correlation
inside square blocks of ``block`` nodes: a resampled map is tiled from blocks
drawn at random positions (with replacement) of the map, and the spread of
the fractions over the resamples is their error.  The error grows with the
block until the block is larger than the correlation length;
:func:`face_fractions` gives it at two block sizes and takes the larger.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["BlockBootstrap", "block_bootstrap_fractions", "face_fractions"]


@dataclasses.dataclass(frozen=True)
class BlockBootstrap:
    """Fractions of ``labels`` on a map and their block-bootstrap standard errors (``block`` nodes a side,
    ``n_boot`` resamples)."""

    labels: tuple
    fraction: np.ndarray
    stderr: np.ndarray
    block: int
    n_boot: int


def _block_counts(hit: np.ndarray, b: int) -> np.ndarray:
    """Number of True nodes in every b×b block of ``hit`` (one per block corner), by an integral image."""
    c = np.zeros((hit.shape[0] + 1, hit.shape[1] + 1), dtype=np.int64)
    c[1:, 1:] = hit.astype(np.int64).cumsum(axis=0).cumsum(axis=1)
    return c[b:, b:] - c[:-b, b:] - c[b:, :-b] + c[:-b, :-b]


def block_bootstrap_fractions(grid, labels=(1, 2, 3, 4, 5, 6), *, block: int, n_boot: int = 500,
                              rng=0) -> BlockBootstrap:
    """The fraction of every label of a 2-D map and its moving-block bootstrap standard error.

    Each resample tiles ``ceil(nx/block) × ceil(ny/block)`` blocks of ``block × block`` nodes whose corners
    are drawn uniformly among the map's positions; the fraction is taken over the resample's nodes.
    """
    g = np.asarray(grid)
    if g.ndim != 2:
        raise ValueError(f"block_bootstrap_fractions needs a 2-D map, got shape {g.shape}")
    b = int(block)
    if not 1 <= b <= min(g.shape):
        raise ValueError(f"block must be between 1 and the map's shorter side {min(g.shape)}, got {block!r}")
    if int(n_boot) < 2:
        raise ValueError(f"n_boot must be at least 2, got {n_boot!r}")
    labels = tuple(labels)
    m = math.ceil(g.shape[0] / b) * math.ceil(g.shape[1] / b)
    counts = np.stack([_block_counts(g == lab, b).ravel() for lab in labels])  # (labels, corners)
    pick = np.random.default_rng(rng).integers(0, counts.shape[1], size=(int(n_boot), m))
    boot = np.stack([c[pick].sum(axis=1) for c in counts]) / float(m * b * b)  # (labels, n_boot)
    frac = np.array([float(np.mean(g == lab)) for lab in labels])
    return BlockBootstrap(labels, frac, boot.std(axis=1, ddof=1), b, int(n_boot))


def face_fractions(grid, *, n_boot: int = 500, rng=0) -> dict:
    """Face fractions (faces 1..6, and the share of throws without a face) of a 2-D map, with the larger of the
    block-bootstrap errors at blocks of 1/8 and 1/4 of the map's shorter side (at least 2 nodes)."""
    g = np.asarray(grid)
    side = min(g.shape)
    small, large = max(2, side // 8), max(2, side // 4)
    gen = np.random.default_rng(rng)
    a = block_bootstrap_fractions(g, block=small, n_boot=n_boot, rng=gen)
    b = block_bootstrap_fractions(g, block=large, n_boot=n_boot, rng=gen)
    faces = {str(lab): {"fraction": float(f), "stderr": float(max(s1, s2)), "stderr_small_block": float(s1),
                        "stderr_large_block": float(s2)}
             for lab, f, s1, s2 in zip(a.labels, a.fraction, a.stderr, b.stderr)}
    return {"faces": faces, "no_face": float(np.mean(g < 1)), "blocks": [small, large], "n_boot": int(n_boot),
            "n_nodes": int(g.size)}
