"""Vertex hunt: triple points found to 1e-9, split candidates reported."""

from __future__ import annotations

import numpy as np
import pytest

from analysis_synthetic import near_miss_classify, sector_classify
from dicetrace.analysis import find_vertices

CENTRE = np.array([0.3141592653589793, 0.2718281828459045])


def test_three_sectors_triple_point_to_1e9():
    # one exact triple point at CENTRE (sector_classify); tol = 1e-9 as asked
    v = find_vertices(sector_classify, (0.0, 1.0), (0.0, 1.0), 32, tol=1e-9)
    assert len(v) == 1
    row = v.iloc[0]
    assert row.status == "vertex"
    assert row.labels == (1, 2, 3)
    assert np.hypot(row.x - CENTRE[0], row.y - CENTRE[1]) < 1e-9
    assert max(row.size_x, row.size_y) < 5e-9  # a small cluster of squares < tol
    assert v.attrs["n_evals"] < 20000


def test_two_triple_points_are_two_vertices():
    c2 = np.array([0.71, 0.63])

    def two(points):
        p = np.asarray(points, dtype=float)
        left = sector_classify(p)
        right = sector_classify(p, centre=tuple(c2), labels=(4, 5, 6))
        return np.where(p[:, 0] < 0.55, left, right)

    v = find_vertices(two, (0.0, 1.0), (0.0, 1.0), 40, tol=1e-9)
    vert = v[v.status == "vertex"]
    found = {tuple(np.round(r, 6)) for r in vert[["x", "y"]].to_numpy()}
    assert (round(CENTRE[0], 6), round(CENTRE[1], 6)) in found
    assert (0.71, 0.63) in found


def test_near_miss_is_reported_split_at_its_gap():
    # 1|2 line and 2|3 parabola pass within delta = 1e-6 without meeting: the
    # candidate must be reported "split" once squares are ~delta (within 4x).
    delta = 1e-6
    v = find_vertices(near_miss_classify, (0.0, 1.0), (0.0, 1.0), 32, tol=1e-9)
    assert (v.status != "vertex").all()
    row = v.iloc[0]
    assert row.status == "split"
    assert row.labels == (1, 2, 3)
    side = 1.0 / 31 / 2**row.depth
    assert delta / 4 < side < 4 * delta
    assert abs(row.x - 0.5) < 1e-5 and abs(row.y - 0.5) < 1e-3


def test_far_apart_vertices_in_one_root_cluster_sparsely():
    # Regression: clustering drew each root's finest squares on a dense boolean
    # image (extent / finest square size per axis). Two triple points 0.02 apart
    # share one starting root; at tol = 1e-12 that image would be ~1e10 x 1e10.
    import time

    a = tuple(CENTRE)
    b = (CENTRE[0] + 0.02, CENTRE[1] + 0.01)

    def two_close(points):
        p = np.asarray(points, dtype=float)
        left = sector_classify(p, centre=a)
        right = sector_classify(p, centre=b, labels=(4, 5, 6))
        return np.where(p[:, 0] < 0.5 * (a[0] + b[0]), left, right)

    t0 = time.perf_counter()
    v = find_vertices(two_close, (0.0, 1.0), (0.0, 1.0), 32, tol=1e-12)
    elapsed = time.perf_counter() - t0
    assert (v.status == "vertex").all() and v.root.nunique() == 1
    side = 1.0 / 31 / 2 ** v.depth.iloc[0]
    assert side < 1e-12
    assert (v.x.max() - v.x.min()) / side > 1e9  # the dense image the old code drew
    for centre, labels in ((a, (1, 2, 3)), (b, (4, 5, 6))):
        row = v[v.labels == labels]
        assert len(row) == 1
        assert np.hypot(row.x.iloc[0] - centre[0], row.y.iloc[0] - centre[1]) < 1e-11
    assert elapsed < 5.0


# -- the memory guard and the triple-box count of study f -------------------------------------------------


def test_guarded_find_vertices_refuses_a_large_image_and_restores_numpy():
    from dicetrace.analysis import vertices as V
    from dicetrace.analysis.vertices import guarded_find_vertices

    ok = guarded_find_vertices(sector_classify, (0.0, 1.0), (0.0, 1.0), 32, tol=1e-6)
    assert (ok["status"] == "vertex").sum() == 1
    with pytest.raises(MemoryError, match="find_vertices asked for"):
        guarded_find_vertices(sector_classify, (0.0, 1.0), (0.0, 1.0), 32, tol=1e-6, limit=10)
    assert V.np is np


def test_triple_boxes_count_squares_with_three_outcomes():
    from dicetrace.analysis.vertices import triple_boxes

    g = np.ones((9, 9), dtype=np.int64)
    g[:, 5:] = 2
    assert triple_boxes(g, 2) == 0  # two outcomes only
    g[:3, :3] = 3  # away from the 1|2 border (columns 4 and 5): no box of 2 intervals holds all three
    assert triple_boxes(g, 2) == 0
    g[0, 4] = 3  # now the closed box of rows 0–2, columns 4–6 holds 3, 1 and 2
    assert triple_boxes(g, 2) == 1
    assert triple_boxes(g, 4) == 1  # boxes of 4 intervals: rows 0–4 × columns 4–8 (columns 0–4 hold no 2)
