"""Wada tests: the merging method and the refinement of boundary segments.

Known answers: the basins of Newton's method for z**3 - 1 on [-1, 1]**2 are
Wada (every boundary point of the Julia set borders all three basins); a pie
of three sectors is not (each ray borders two sectors only); Attractors.jl's
stripe grids (test/basins/wada_tests.jl).
"""

from __future__ import annotations

import numpy as np
import pytest

from analysis_synthetic import newton_classify, sample_grid, sector_classify
from dicetrace.analysis import wada_grid_test, wada_merge_test

UNIT = [(0.0, 1.0), (0.0, 1.0)]


def test_wada_merge_newton_vs_pie(newton_grid):
    w = wada_merge_test(newton_grid, r_max=5)
    assert w.wada and w.r_wada <= 3
    pie = sample_grid(sector_classify, UNIT, (300, 300))
    wp = wada_merge_test(pie, r_max=5)
    assert not wp.wada
    assert wp.far_fraction[-1] > 0.5  # most of each ray borders two sectors only


def test_wada_merge_stripes_as_attractors_jl():
    # Attractors.jl test/basins/wada_tests.jl: stripes 1111 2222 3333 are not
    # Wada; 123123... are (every boundary node borders all three labels).
    wide = np.repeat(np.array([1] * 4 + [2] * 4 + [3] * 4)[:, None], 12, axis=1)
    assert not wada_merge_test(wide, r_max=2).wada
    thin = np.repeat(np.array([1, 2, 3] * 4)[:, None], 12, axis=1)
    w = wada_merge_test(thin, r_max=2, tol=0.0)
    assert w.r_wada == 1  # as Attractors.jl's test_wada_merge(M, 1) == 0
    with pytest.raises(ValueError):
        wada_merge_test(np.array([[1, 2], [2, 1]]))


def test_wada_grid_method_newton_vs_pie(newton_grid):
    # Newton: the fraction of refined boundary segments showing all three
    # basins grows to 1 (0.996 at 24 levels); threshold 0.95 as Daza et al.
    # (2015) use W -> 1. The pie's rays never show a third label.
    rng = np.random.default_rng(0)
    w = wada_grid_test(newton_classify, newton_grid, [(-1, 1), (-1, 1)], max_segments=1000, rng=rng)
    assert w.wada and w.wada_fraction[-1] > 0.95
    assert np.all(np.diff(w.wada_fraction) >= 0)
    pie = sample_grid(sector_classify, UNIT, (200, 200))
    wp = wada_grid_test(sector_classify, pie, UNIT, max_segments=500, rng=rng)
    assert not wp.wada and wp.wada_fraction[-1] < 0.05
