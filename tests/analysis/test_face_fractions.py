"""Face fractions with moving-block bootstrap errors (:mod:`dicetrace.analysis.face_fractions`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.analysis.face_fractions import block_bootstrap_fractions, face_fractions


def _iid(n=60, seed=0):
    return np.random.default_rng(seed).integers(1, 7, size=(n, n))


def _cells(n=120, width=20, seed=0):
    """A map of square cells ``width`` nodes a side, each of one random face: strongly correlated nodes."""
    faces = np.random.default_rng(seed).integers(1, 7, size=(n // width, n // width))
    return np.kron(faces, np.ones((width, width), dtype=np.int64))


def test_independent_nodes_give_the_binomial_error():
    g = _iid()
    bb = block_bootstrap_fractions(g, block=1, n_boot=1000, rng=1)
    binom = np.sqrt(bb.fraction * (1 - bb.fraction) / g.size)
    assert np.allclose(bb.fraction, [np.mean(g == k) for k in range(1, 7)])
    assert np.all(np.abs(bb.stderr / binom - 1) < 0.2)


def test_correlated_nodes_give_a_much_larger_error_than_the_binomial():
    g = _cells()
    small = block_bootstrap_fractions(g, block=1, n_boot=50, rng=1)
    big = block_bootstrap_fractions(g, block=20, n_boot=500, rng=1)
    binom = np.sqrt(small.fraction * (1 - small.fraction) / g.size)
    present = small.fraction > 0
    assert np.all(big.stderr[present] > 4 * binom[present])  # 36 cells, not 14400 throws
    # a map of 36 independent cells: the error of a fraction is about that of 36 draws
    cells = np.sqrt(small.fraction * (1 - small.fraction) / 36)
    assert np.all(np.abs(big.stderr[present] / cells[present] - 1) < 0.5)


def test_face_fractions_takes_the_larger_of_two_blocks_and_counts_throws_without_a_face():
    g = _cells()
    g[0, :10] = -1  # ten throws that did not settle
    r = face_fractions(g, n_boot=200, rng=0)
    assert r["blocks"] == [15, 30] and r["n_nodes"] == g.size
    assert r["no_face"] == pytest.approx(10 / g.size)
    total = sum(f["fraction"] for f in r["faces"].values()) + r["no_face"]
    assert total == pytest.approx(1.0)
    for f in r["faces"].values():
        assert f["stderr"] == max(f["stderr_small_block"], f["stderr_large_block"])
        assert math.isfinite(f["stderr"]) and f["stderr"] >= 0


@pytest.mark.parametrize("grid, block, why", [(np.ones((4, 4, 4)), 2, "2-D"), (np.ones((10, 10)), 11, "block"),
                                              (np.ones((10, 10)), 0, "block")])
def test_bad_input_is_refused(grid, block, why):
    with pytest.raises(ValueError, match=why):
        block_bootstrap_fractions(grid, block=block)
