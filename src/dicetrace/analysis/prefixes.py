"""Topology as an entropy: the growth rate of distinct contact-sequence prefixes, in nats per contact set.

The writeup labels a throw by its sequence of contact sets.  Counting the
distinct sequences of a sample saturates at the sample size, so the count
says more about the sample than about the die.  The growth rate of the
number ``N(n)`` of distinct length-``n`` prefixes, ``N(n) ~ exp(h n)``, is
the topological entropy of the symbolic dynamics (nats per contact set); it
is estimated where ``N(n)`` is still far below the number of sequences
(``N(n) ≤ max_fill · M``), and checked against half and a quarter of the
sample.

A penalty ground adds micro-bounces (a corner leaving and re-entering the
ground within a few steps); :func:`coarse_grain` drops every set that lasts
fewer than ``min_steps`` steps and merges the repeats this leaves.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from .boundaries import fit_power_law

__all__ = ["coarse_grain", "prefix_counts", "PrefixEntropy", "prefix_entropy"]


def coarse_grain(sets, steps, end_step: int, *, min_steps: int) -> tuple:
    """The contact sets that last at least ``min_steps`` steps, consecutive repeats merged.

    ``sets[i]`` is first seen at ``steps[i]`` and lasts until ``steps[i+1]``
    (the last one until ``end_step``).  The first set (in the air, before the
    first contact) is always kept.
    """
    s = np.asarray(sets)
    st = np.append(np.asarray(steps, dtype=np.int64), int(end_step))
    dur = np.diff(st)
    out: list[int] = []
    for i, v in enumerate(s.tolist()):
        if i > 0 and dur[i] < min_steps:
            continue
        if not out or out[-1] != v:
            out.append(int(v))
    return tuple(out)


def prefix_counts(sequences: Sequence[Sequence], max_len: int) -> np.ndarray:
    """``N(n)`` for n = 1 … ``max_len``: distinct length-n prefixes among the sequences at least n long."""
    out = np.zeros(int(max_len), dtype=np.int64)
    for n in range(1, int(max_len) + 1):
        out[n - 1] = len({tuple(q[:n]) for q in sequences if len(q) >= n})
    return out


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


def _fit(counts: np.ndarray, m: int, n_min: int, max_fill: float) -> tuple[float, float, tuple[int, int]]:
    n = np.arange(1, len(counts) + 1)
    ok = (n >= n_min) & (counts <= max_fill * m) & (counts > 0)
    if ok.sum() < 3:
        return math.nan, math.nan, (0, 0)
    fit = fit_power_law(np.exp(n[ok]), counts[ok])  # ln N = h n + c
    return float(fit.slope), float(fit.slope_stderr), (int(n[ok][0]), int(n[ok][-1]))


def prefix_entropy(sequences: Sequence[Sequence], *, max_len: int = 60, n_min: int = 2, max_fill: float = 0.1,
                   rng: np.random.Generator | int = 0) -> PrefixEntropy:
    """The growth rate ``h`` of ``N(n)`` on the lengths where ``N(n) ≤ max_fill · M`` (``M`` sequences long
    enough), with the same fit on a random half and quarter of the sample (the sample-size check)."""
    seqs = [tuple(q) for q in sequences]
    m = len(seqs)
    counts = prefix_counts(seqs, max_len)
    h, se, rng_n = _fit(counts, m, n_min, max_fill)
    gen = np.random.default_rng(rng)
    subs = []
    for frac in (2, 4):
        pick = gen.choice(m, size=max(1, m // frac), replace=False)
        sub = [seqs[i] for i in pick]
        subs.append(_fit(prefix_counts(sub, max_len), len(sub), n_min, max_fill)[0])
    return PrefixEntropy(h, se, rng_n, counts, subs[0], subs[1], m)
