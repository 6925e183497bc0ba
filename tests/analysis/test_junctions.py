"""Triple-junction box counts (analysis.junctions) on maps whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest
from analysis_synthetic import newton_classify, sample_grid

from dicetrace.analysis.junctions import (
    junction_box_counts, junction_dimension, strip_map, three_sector_map,
)


def test_three_sectors_have_one_vertex_of_dimension_zero():
    # Known answer: three rays meet at one point, so every tiling has exactly one box where the three
    # outcomes meet (the point is not on a box edge for this irrational centre), at all 7 scales: D = 0 exactly.
    g = three_sector_map(513)
    c = junction_box_counts(g)
    assert len(c.box_sizes) >= 6
    assert np.all(c.meet3 == 1.0)
    d = junction_dimension(c.box_sizes, c.meet3)
    assert d.dimension == 0.0 and not d.clamped and d.n_scales == 7
    # the box found holds the vertex: centre (0.5 + 1/2π, 0.5 − 1/3e) in grid units, within one box (1 interval)
    true = np.array([0.5 + 1 / (2 * np.pi), 0.5 - 1 / (3 * np.e)]) * 512
    assert len(c.centres_meet3) == 1
    assert np.all(np.abs(c.centres_meet3[0] - true) <= 1.0)


def test_strip_has_three_outcomes_but_no_junction():
    # Negative control: two parallel borders 0.02 apart (≈ 10 intervals). Boxes wider than the strip hold three
    # outcomes (the old count sees them), but no box has the three pairs of neighbours: meet3 = 0 at all scales.
    g = strip_map(513)
    c = junction_box_counts(g)
    assert np.all(c.meet3 == 0)
    assert c.any3[c.box_sizes >= 16].min() > 0
    assert np.isnan(junction_dimension(c.box_sizes, c.meet3).dimension)


def test_random_labels_fill_the_plane():
    # Known answer: i.i.d. labels put junctions everywhere, N(b) ~ (n/b)² : D = 2 in the limit. On 7 scales of
    # a 513² grid the smallest boxes (2×2 nodes) cannot always hold three labels, so the fit gives 1.8-1.9;
    # tolerance 0.25 from that finite-box bias, measured here.
    g = np.random.default_rng(1).integers(1, 4, (513, 513))
    c = junction_box_counts(g)
    d = junction_dimension(c.box_sizes, c.meet3)
    assert d.dimension == pytest.approx(2.0, abs=0.25)


@pytest.mark.slow  # about 0.7 s
def test_newton_basins_meet_along_their_whole_boundary():
    # Newton z³−1: a Wada boundary (every boundary point touches all three basins), so the junction set is the
    # boundary itself, of dimension between 1 and 2 (≈ 1.42, e.g. Aguirre, Viana & Sanjuán 2009, Rev. Mod. Phys.
    # 81:333); box counting on 513² over 7 scales, tolerance: strictly above a curve (1) and below 1.6.
    g = sample_grid(newton_classify, [(-1.0, 1.0), (-1.0, 1.0)], (513, 513))
    c = junction_box_counts(g)
    d = junction_dimension(c.box_sizes, c.meet3)
    assert 1.0 < d.dimension < 1.6


def test_dimension_is_never_negative():
    # A count that grows with the box (noise around a point) is clamped to 0 and flagged.
    d = junction_dimension([1, 2, 4, 8, 16, 32], [1, 1, 2, 2, 3, 3])
    assert d.dimension == 0.0 and d.clamped and d.slope > 0


def test_excluded_labels_do_not_make_junctions():
    g = three_sector_map(129, labels=(1, 2, 0))
    c = junction_box_counts(g)
    assert np.all(c.meet3 == 0)
    c = junction_box_counts(g, exclude=())
    assert np.all(c.meet3 >= 1)


def test_junction_row_of_the_three_sectors():
    from dicetrace.analysis.junctions import junction_row

    r = junction_row("three sectors", three_sector_map(129), model="control")
    assert r["map"] == "three sectors" and r["model"] == "control" and r["res"] == 129
    assert r["dim_meet3"] == 0.0 and r["n_vertex_boxes_smallest"] == 1
