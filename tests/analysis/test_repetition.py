"""Repetition: period vectors of label grids and their 3-D connectivity."""

from __future__ import annotations

import numpy as np
import pytest

from analysis_synthetic import lattice_grid
from dicetrace.analysis import find_periods, label_autocorrelation, periodic_cells_connected


def _same_lattice(found: np.ndarray, true: np.ndarray) -> bool:
    """Whether two 2x2 bases (columns) span the same integer lattice."""
    u = np.linalg.solve(true.astype(float), found.astype(float))
    return np.allclose(u, np.rint(u), atol=1e-9) and abs(round(np.linalg.det(u))) == 1


def test_oblique_lattice_recovered_exactly():
    # Grid periodic under a = (12, 0), b = (5, 17) exactly (integer lattice):
    # the reduced basis must span the same lattice, strength ~1 (exact
    # periodicity; the normalisation by the global mean allows ~1e-2 excess).
    a, b = np.array([12, 0]), np.array([5, 17])
    g = lattice_grid((128, 96), a, b)
    per = find_periods(g, spacing=(0.01, 0.02))
    assert len(per) == 2
    found = per[["di", "dj"]].to_numpy().T
    assert _same_lattice(found, np.column_stack([a, b]))
    assert (per.strength > 0.95).all()
    assert per.dx.tolist() == [0.01 * v for v in per.di]
    assert per.dy.tolist() == [0.02 * v for v in per.dj]
    # the discs (label 2) alone show the same lattice
    per2 = find_periods(g, label=2)
    assert _same_lattice(per2[["di", "dj"]].to_numpy().T, np.column_stack([a, b]))
    # label 5 is a band of constant v = j / 17: stripes, lattice (1, 0), (0, 17)
    per5 = find_periods(g, label=5)
    assert _same_lattice(per5[["di", "dj"]].to_numpy().T, np.array([[1, 0], [0, 17]]))


def test_oblique_stripes_give_their_period_lattice():
    # stripes where (3 i + 2 j) mod 20 < 8: invariant exactly under the lattice
    # {(di, dj): 3 di + 2 dj = 0 mod 20}, basis (2, -3), (4, 4) (index 20).
    i, j = np.indices((128, 96))
    g = np.where((3 * i + 2 * j) % 20 < 8, 1, 3)
    per = find_periods(g)
    found = per[["di", "dj"]].to_numpy().T
    assert _same_lattice(found, np.array([[2, 4], [-3, 4]]))


def test_random_labels_have_no_period():
    # i.i.d. labels: C(lag) ~ N(0, 1/overlap) with overlap >= 64*64 nodes here,
    # so |C| < 0.1 (> 6 sigma) and nothing reaches min_strength = 0.3.
    rng = np.random.default_rng(12345)
    g = rng.integers(1, 7, size=(128, 128))
    assert find_periods(g).empty
    C = label_autocorrelation(g)
    assert C[127, 127] == 1.0
    off = C[64:-64, 64:-64].copy()
    off[63, 63] = 0.0
    assert np.abs(off).max() < 0.1


def test_repeated_regions_connect_only_through_a_bridge():
    a, b = np.array([12, 0]), np.array([5, 17])
    g2 = lattice_grid((96, 96), a, b)
    stack = np.repeat(g2[:, :, None], 5, axis=2)  # straight extrusion: disjoint columns
    res = periodic_cells_connected(stack, (12, 0), label=2)
    assert len(res) > 10
    assert (res.overlap > 0.99).all()  # the translate lands on one partner cell
    assert not res.connected.any()
    bridged = stack.copy()
    bridged[:, :, 4] = 2  # a lid of label 2 joins every column
    res2 = periodic_cells_connected(bridged, (12, 0), label=2)
    assert res2.connected.all()


# -- the repetition measures of one map (studies c and l) ------------------------------------------------


def test_texture_is_the_denser_half_of_the_borders():
    from dicetrace.analysis.repetition import texture_labels

    g = np.ones((60, 60), dtype=np.int64)
    g[:, :30] = np.where(np.arange(30) % 2, 1, 2)[None, :]  # left half: a border at every node
    tex = texture_labels(g, 2.0)
    assert set(np.unique(tex)) == {0, 1}
    assert tex[:, :25].all() and not tex[:, 35:].any()


def test_off_centre_max_skips_the_central_peak():
    from dicetrace.analysis.repetition import off_centre_max

    corr = np.zeros((41, 41))
    corr[20, 20] = 1.0
    corr[20, 21] = 0.9  # inside the excluded radius
    corr[20, 28] = 0.4  # beyond it, within half the lags
    corr[20, 40] = 0.8  # beyond half the lags
    assert off_centre_max(corr, 3) == pytest.approx(0.4)


def test_stripe_spacing_is_the_distance_between_stripes():
    from dicetrace.analysis.repetition import stripe_spacing

    rows = [{"dx": 0.0, "dy": 1.0}, {"dx": 3.0, "dy": 5.0}]  # along the stripes, then across them
    assert stripe_spacing(rows) == pytest.approx(3.0)
    assert stripe_spacing(rows[:1]) is None


def test_repetition_stats_find_the_period_of_a_lattice():
    from types import SimpleNamespace

    from dicetrace.analysis.repetition import repetition_stats

    g = np.tile(np.repeat(np.repeat(np.array([[1, 2], [3, 4]]), 5, axis=0), 5, axis=1), (4, 4))  # period 10 nodes
    st = repetition_stats(SimpleNamespace(labels=g, spacing=(0.1, 0.1)))
    assert st["outcome_offcentre_max_corr"] == pytest.approx(1.0)
    lengths = sorted(p["length"] for p in st["outcome_periods"])
    assert lengths[0] == pytest.approx(1.0)  # 10 nodes of 0.1
