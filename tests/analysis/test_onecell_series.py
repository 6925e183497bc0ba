"""The measures of study p: the join counts of a stack (analysis.onecell), the bootstrap of a period vector
(analysis.repetition) and the sub-cells of a cell by a finer label (analysis.prefixes), on grids with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from analysis_synthetic import lattice_grid

from dicetrace.analysis.onecell import join_counts, min_cell_nodes
from dicetrace.analysis.prefixes import subcell_stats
from dicetrace.analysis.repetition import period_bootstrap


def _u_stack(bridge: bool) -> np.ndarray:
    """A 20×20×6 stack of face 1 with two face-2 squares in slice z = 0, joined through z ≥ 2 by a face-2 bridge
    when ``bridge``."""
    g = np.ones((20, 20, 6), dtype=np.int64)
    g[2:7, 2:7, :3] = 2
    g[12:17, 2:7, :3] = 2
    if bridge:
        g[2:17, 2:7, 2] = 2
    return g


def test_two_cells_joined_through_z_are_counted_joined():
    j = join_counts(_u_stack(True), min_area=0.05)  # 20 nodes: the two 25-node squares, and face 1 (350 nodes)
    assert (j["n_cells"], j["n_joined"], j["n_components"]) == (3, 2, 2)
    assert j["fraction"] == pytest.approx(2 / 3) and j["stderr"] == pytest.approx(math.sqrt(2 / 9 / 3))
    assert j["area_fraction"] == pytest.approx(50 / 400)


def test_two_cells_apart_in_3d_are_not_joined():
    j = join_counts(_u_stack(False), min_area=0.05)
    assert (j["n_cells"], j["n_joined"], j["n_components"]) == (3, 0, 3) and j["fraction"] == 0.0


def test_the_cells_counted_are_a_share_of_the_slice():
    # the same share of the slice at every resolution: 0.5 % is 2 nodes at 16² (the floor), 12 at 48²
    assert [min_cell_nodes(n, n, 0.005) for n in (16, 24, 32, 48)] == [2, 3, 6, 12]
    j = join_counts(_u_stack(True), min_area=0.1)  # 40 nodes: only face 1 is counted
    assert (j["n_cells"], j["n_joined"]) == (1, 0)
    assert math.isnan(join_counts(_u_stack(True), min_area=2.0)["fraction"])


def test_the_bootstrap_finds_a_lattice_period_with_a_small_error():
    # Known answer: a map periodic under (20, 3), (−4, 17); the peak at (20, 3) is found to a fraction of a node,
    # and tiles drawn from a periodic map all put it there, so the error is a small fraction of a node
    g = lattice_grid((160, 160), (20, 3), (-4, 17))
    b = period_bootstrap(g, (20, 3), n_boot=50, rng=0)
    assert b["interior"] and b["interior_fraction"] == 1.0
    assert abs(b["di"] - 20) < 0.5 and abs(b["dj"] - 3) < 0.5
    assert 0 <= b["di_stderr"] < 0.2 and 0 <= b["dj_stderr"] < 0.2
    assert b["strength"] > 0.8


def test_noise_has_no_stable_peak_at_an_arbitrary_lag():
    # Null case: at an arbitrary lag in white noise the correlation has no maximum; the draws' peaks scatter over
    # the searched box (most on its edge), and the error is of the order of the box, not of a node's fraction
    g = np.random.default_rng(3).integers(1, 4, (120, 120))
    b = period_bootstrap(g, (30, 7), radius=2, n_boot=60, rng=1)
    assert abs(b["strength"]) < 0.1
    assert b["interior_fraction"] < 0.5
    assert max(b["di_stderr"], b["dj_stderr"]) > 0.5


def test_subcells_of_a_cell_split_by_a_finer_label():
    mask = np.zeros((6, 6), dtype=bool)
    mask[:4, :4] = True  # a 16-node cell
    lab = np.full((6, 6), "x", dtype=object)
    lab[:4, :2] = "a-b"  # 8 nodes, one region
    lab[:4, 2:4] = "a-c"  # 8 nodes, one region ...
    lab[0, 3] = "a-b"  # ... but one node of them carries the first label: a third, one-node region
    s = subcell_stats(lab, mask)
    assert (s["n_nodes"], s["n_labels"], s["n_subcells"], s["n_singletons"]) == (16, 2, 3, 1)
    assert s["frac_nodes_in_singletons"] == pytest.approx(1 / 16) and s["largest_frac"] == pytest.approx(8 / 16)
    assert s["simpson"] == pytest.approx((9 * 8 + 7 * 6) / (16 * 15))
    with pytest.raises(ValueError, match="no node"):
        subcell_stats(lab, np.zeros_like(mask))
