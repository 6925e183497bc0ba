"""Topology as an entropy: the growth rate of distinct contact-sequence prefixes, in nats per contact set.

The writeup labels a throw by its sequence of contact sets.  Counting the
distinct sequences of a sample saturates at the sample size, so the count
says more about the sample than about the die.  The growth rate of the
number ``N(n)`` of distinct length-``n`` prefixes, ``N(n) ~ exp(h n)``, is
the topological entropy of the symbolic dynamics (nats per contact set); it
is estimated where ``N(n)`` is still far below the number of sequences
that long (``N(n) ≤ max_fill · M(n)``), and checked against half and a
quarter of the sample.

A penalty ground adds micro-bounces (a corner leaving and re-entering the
ground within a few steps); :func:`coarse_grain` drops every set that lasts
fewer than ``min_steps`` steps and merges the repeats this leaves.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .boundaries import fit_power_law

__all__ = ["coarse_grain", "prefix_counts", "PrefixEntropy", "prefix_entropy", "simpson", "prefix_codes",
           "fast_components", "subcell_stats"]


def coarse_grain(sets, steps, end_step: int, *, min_steps: int) -> tuple:
    """The contact sets that last at least ``min_steps`` steps, consecutive repeats merged.

    ``sets[i]`` is first seen at ``steps[i]`` and lasts until ``steps[i+1]``
    (the last one until ``end_step``).  The first set (in the air, before the
    first contact) is always kept.  The times may be steps (integers) or, for
    exact contact events (``simulate_batch(..., record=Record.events_only())``), seconds:
    ``end_step`` and ``min_steps`` in the same unit.
    """
    s = np.asarray(sets)
    st = np.append(np.asarray(steps, dtype=np.float64), float(end_step))
    dur = np.diff(st)
    out: list[int] = []
    for i, v in enumerate(s.tolist()):
        if i > 0 and dur[i] < min_steps:
            continue
        if not out or out[-1] != v:
            out.append(int(v))
    return tuple(out)


def prefix_counts(sequences: Sequence[Sequence], max_len: int, *, with_alive: bool = False):
    """``N(n)`` for n = 1 … ``max_len``: distinct length-n prefixes among the sequences at least n long.

    With ``with_alive`` also ``M(n)``, the number of sequences at least n long.
    """
    out = np.zeros(int(max_len), dtype=np.int64)
    alive = np.zeros(int(max_len), dtype=np.int64)
    for n in range(1, int(max_len) + 1):
        long_enough = [tuple(q[:n]) for q in sequences if len(q) >= n]
        out[n - 1] = len(set(long_enough))
        alive[n - 1] = len(long_enough)
    return (out, alive) if with_alive else out


@dataclasses.dataclass(frozen=True)
class PrefixEntropy:
    """``h`` (nats per set) ± ``stderr`` over lengths ``n_range``; ``counts``; ``h_half``, ``h_quarter`` (subsamples)."""

    h: float
    stderr: float
    n_range: tuple[int, int]
    counts: np.ndarray
    h_half: float
    h_quarter: float
    n_sequences: int


def _fit(counts: np.ndarray, alive: np.ndarray, min_count: int, max_fill: float) -> tuple[float, float, tuple]:
    n = np.arange(1, len(counts) + 1)
    m = alive[0] if len(alive) else 0
    ok = (counts >= min_count) & (counts <= max_fill * alive) & (alive >= 0.5 * m)
    if ok.sum() < 3:
        return math.nan, math.nan, (0, 0)
    fit = fit_power_law(np.exp(n[ok]), counts[ok])  # ln N = h n + c
    return float(fit.slope), float(fit.slope_stderr), (int(n[ok][0]), int(n[ok][-1]))


def prefix_entropy(sequences: Sequence[Sequence], *, max_len: int = 60, min_count: int = 5,
                   max_fill: float = 0.1, rng: np.random.Generator | int = 0) -> PrefixEntropy:
    """The growth rate ``h`` of ``N(n)``, fitted where ``min_count ≤ N(n) ≤ max_fill · M(n)`` and ``M(n) ≥ M/2``.

    ``M(n)`` is the number of sequences at least ``n`` long (``M`` all of
    them): the fit stays where the count is neither in the deterministic
    start (``N < min_count``) nor limited by the sample (``N`` near ``M(n)``),
    nor by the sequences that have ended.  The same fit on a random half and
    quarter of the sample is the sample-size check: a rate that depends on
    the sample size is not the die's.
    """
    seqs = [tuple(q) for q in sequences]
    m = len(seqs)
    counts, alive = prefix_counts(seqs, max_len, with_alive=True)
    h, se, rng_n = _fit(counts, alive, min_count, max_fill)
    gen = np.random.default_rng(rng)
    subs = []
    for frac in (2, 4):
        pick = gen.choice(m, size=max(1, m // frac), replace=False)
        sub = [seqs[i] for i in pick]
        subs.append(_fit(*prefix_counts(sub, max_len, with_alive=True), min_count, max_fill)[0])
    return PrefixEntropy(h, se, rng_n, counts, subs[0], subs[1], m)


def simpson(counts: np.ndarray) -> float:
    """Probability that two throws drawn (without replacement) share the label."""
    n = counts.sum()
    return float((counts * (counts - 1)).sum() / (n * (n - 1))) if n > 1 else float("nan")


def prefix_codes(seqs: np.ndarray, kmax: int) -> list[np.ndarray]:
    """Integer class of every throw's first k contact sets, k = 1..kmax (equal code = equal prefix).

    Sequences shorter than k keep their whole sequence as the prefix (a sentinel pads them).
    """
    parts = [str(q).split("-") for q in seqs.ravel()]
    n = len(parts)
    width = max(len(p) for p in parts)
    mat = np.full((n, max(width, kmax)), -1, dtype=np.int64)  # -1: the sequence has ended
    for i, p in enumerate(parts):
        mat[i, : len(p)] = [int(x) for x in p]  # a set's text (ascending node digits) read as a number
    codes, cur = [], np.zeros(n, dtype=np.int64)
    for k in range(kmax):
        _, cur = np.unique(cur * 1_000_000_000 + mat[:, k], return_inverse=True)
        cur = cur.astype(np.int64).ravel()
        codes.append(cur.reshape(seqs.shape))
    return codes


def fast_components(codes: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, int]:
    """Connected regions of equal code (face neighbours) among the nodes in ``mask``; 0 outside.

    Same result as ``label_cells`` restricted to ``mask``, in one pass over the edges (label_cells
    loops over the labels, which is slow for tens of thousands of contact sequences).
    """
    idx = np.arange(codes.size).reshape(codes.shape)
    rows, cols = [], []
    for off in ((1, 0), (0, 1)):
        a = (slice(0, codes.shape[0] - off[0]), slice(0, codes.shape[1] - off[1]))
        b = (slice(off[0], None), slice(off[1], None))
        same = (codes[a] == codes[b]) & mask[a] & mask[b]
        rows.append(idx[a][same])
        cols.append(idx[b][same])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r), dtype=np.int8), (r, c)), shape=(codes.size, codes.size))
    _, lab = connected_components(graph, directed=False)
    lab = lab.reshape(codes.shape)
    out = np.zeros(codes.shape, dtype=np.int64)
    _, inv = np.unique(lab[mask], return_inverse=True)
    out[mask] = inv.ravel() + 1
    return out, int(inv.max() + 1) if mask.any() else 0


def subcell_stats(labels: np.ndarray, mask: np.ndarray) -> dict:
    """How the nodes in ``mask`` (one outcome cell of a 2-D map) split by a finer label (a contact sequence's text):
    ``n_nodes``, ``n_labels`` (distinct labels), ``n_subcells`` (connected regions of one label, face neighbours),
    ``n_singletons`` and ``frac_nodes_in_singletons`` (one-node regions), ``largest_frac`` (the largest region's
    share of the nodes), ``simpson`` (two nodes drawn share the label: :func:`simpson`)."""
    mask = np.asarray(mask, dtype=bool)
    lab = np.asarray(labels)
    if lab.shape != mask.shape:
        raise ValueError(f"labels {lab.shape} and mask {mask.shape} must have one shape")
    n = int(mask.sum())
    if n == 0:
        raise ValueError("the mask holds no node")
    uniq, inv, counts = np.unique(lab[mask].astype(str), return_inverse=True, return_counts=True)
    codes = np.full(lab.shape, -1, dtype=np.int64)
    codes[mask] = inv.ravel()
    ids, n_sub = fast_components(codes, mask)
    sizes = np.bincount(ids[mask])[1:]
    return {"n_nodes": n, "n_labels": int(len(uniq)), "n_subcells": int(n_sub),
            "n_singletons": int((sizes == 1).sum()), "frac_nodes_in_singletons": float(sizes[sizes == 1].sum() / n),
            "largest_frac": float(sizes.max() / n), "simpson": simpson(counts)}
