"""Cells: connected components of equal label in 2-D and 3-D grids."""

from __future__ import annotations

import numpy as np
import pytest

from dicetrace.analysis import cells_table, label_cells, same_cell, slice_cell_components


def _checkerboard(nblocks=8, b=4, labels=(1, 2)):
    i, j = np.indices((nblocks * b, nblocks * b)) // b
    return np.where((i + j) % 2 == 0, labels[0], labels[1])


def test_checkerboard_face_vs_full_connectivity():
    # Exact: 8x8 blocks of 4x4 nodes. Face connectivity: every block is a cell
    # (64 cells of 16 nodes). Full connectivity joins blocks of one colour
    # through their corners: 2 cells of 512 nodes.
    g = _checkerboard()
    ids, n = label_cells(g)
    assert n == 64
    assert np.bincount(ids.ravel())[1:].tolist() == [16] * 64
    ids_full, n_full = label_cells(g, connectivity="full")
    assert n_full == 2
    tab = cells_table(g, connectivity="full")
    assert tab["size"].tolist() == [512, 512]
    assert tab["label"].tolist() == [1, 2]


def test_cells_table_geometry():
    g = np.ones((10, 6), dtype=np.int64)
    g[2:5, 1:3] = 4  # a 3 x 2 block
    g[9, 5] = -1  # a one-node cell of "did not settle"
    tab = cells_table(g, extent=[(0.0, 0.9), (1.0, 1.5)])
    assert len(tab) == 3
    block = tab[tab.label == 4].iloc[0]
    assert block["size"] == 6
    assert block["bbox"] == ((2, 4), (1, 2))
    assert block["centroid"] == pytest.approx((3.0, 1.5))
    # slice units: x = 0.1 i, y = 1 + 0.1 j
    assert block["centroid_slice"] == pytest.approx((0.3, 1.15))
    assert not block["touches_edge"]
    lone = tab[tab.label == -1].iloc[0]
    assert lone["size"] == 1 and lone["touches_edge"]
    # excluding -1 leaves the node without a cell
    ids, n = label_cells(g, exclude=(-1,))
    assert n == 2 and ids[9, 5] == 0


def test_cells_on_contact_sequence_labels():
    g = np.array(
        [["0-3", "0-3", "0-1-3"], ["0-3", "0-5", "0-1-3"], ["0-5", "0-5", "0-3"]], dtype=object
    )
    tab = cells_table(g)
    assert sorted(zip(tab.label, tab["size"])) == [("0-1-3", 2), ("0-3", 1), ("0-3", 3), ("0-5", 3)]


def _u_tube_stack():
    """Background 1; label 2 in three columns along k; columns A and B joined
    by a bridge in the top slice (a U-tube), column C isolated."""
    g = np.ones((16, 8, 6), dtype=np.int64)
    g[2:5, 2:5, :] = 2  # A
    g[10:13, 2:5, :] = 2  # B
    g[2:13, 2:5, 5] = 2  # bridge A-B at k = 5
    g[6:8, 6:8, :4] = 2  # C, never touching
    return g


def test_same_cell_through_third_dimension():
    g = _u_tube_stack()
    assert same_cell(g, (3, 3, 0), (11, 3, 0))  # A and B meet at k = 5
    assert not same_cell(g, (3, 3, 0), (6, 6, 0))  # C is its own cell
    assert not same_cell(g, (3, 3, 0), (0, 0, 0))  # different labels
    ids, _ = label_cells(g)
    assert same_cell(g, (11, 3, 2), (2, 2, 4), cell_ids=ids)


def test_slice_cell_components_groups_repeated_regions():
    g = _u_tube_stack()
    tab = slice_cell_components(g, 0)
    twos = tab[tab.label == 2].sort_values("centroid")
    # slice 0 shows three separate 2-cells; A and B are one 3-D cell, C another
    assert len(twos) == 3
    comp = dict(zip([c[0] for c in twos.centroid], twos.component_3d))
    assert comp[3.0] == comp[11.0] != comp[6.5]
    assert twos.set_index(twos.centroid.map(lambda c: c[0])).n_cells_in_component.to_dict() == {
        3.0: 2,
        6.5: 1,
        11.0: 2,
    }


def _label_cells_per_label(grid, connectivity="face", exclude=()):
    """The former implementation (one ndimage.label per distinct label), as reference."""
    from scipy import ndimage

    arr = np.asarray(grid)
    if arr.dtype.kind in "iub":
        codes = arr.astype(np.int64)
        uniques = [v.item() for v in np.unique(codes)]
    else:
        import pandas as pd

        c, u = pd.factorize(pd.Series(arr.ravel(), dtype=object), sort=True)
        codes, uniques = c.astype(np.int64).reshape(arr.shape), list(u)
    st = ndimage.generate_binary_structure(arr.ndim, 1 if connectivity == "face" else arr.ndim)
    ids = np.zeros(arr.shape, dtype=np.int64)
    n = 0
    for i, lab in enumerate(uniques):
        if lab in set(exclude):
            continue
        lab_arr, k = ndimage.label(codes == (lab if arr.dtype.kind in "iub" else i), structure=st)
        ids[lab_arr > 0] = lab_arr[lab_arr > 0] + n
        n += int(k)
    return ids, n


@pytest.mark.parametrize("connectivity", ["face", "full"])
@pytest.mark.parametrize("shape", [(40, 37), (1, 25), (12, 11, 9)])
@pytest.mark.parametrize("nlabels", [3, 60])
def test_label_cells_matches_per_label_reference(connectivity, shape, nlabels):
    rng = np.random.default_rng([len(connectivity), nlabels, *shape])
    # coarse blobs plus noise: cells of many sizes, many labels
    g = rng.integers(-1, nlabels, size=shape)
    g = np.where(rng.random(shape) < 0.6, np.roll(g, 1, axis=0), g)
    for exclude in ((), (-1,), (-1, 0, 2)):
        ids, n = label_cells(g, connectivity=connectivity, exclude=exclude)
        ref_ids, ref_n = _label_cells_per_label(g, connectivity, exclude)
        assert n == ref_n
        np.testing.assert_array_equal(ids, ref_ids)
        assert ids.dtype == np.int64
    # string labels (contact sequences) take the factorised path
    s = np.array([f"0-{v}" for v in g.ravel()], dtype=object).reshape(shape)
    ids, n = label_cells(s, connectivity=connectivity, exclude=("0--1",))
    ref_ids, ref_n = _label_cells_per_label(s, connectivity, ("0--1",))
    assert n == ref_n
    np.testing.assert_array_equal(ids, ref_ids)


def test_label_cells_fast_with_many_labels():
    # Regression: one ndimage.label per distinct label took ~300 s for 15k
    # contact-sequence labels on a 301 x 301 grid; now a single graph pass.
    import time

    rng = np.random.default_rng(7)
    g = rng.integers(0, 10_000, size=(300, 300))
    s = g.astype(str).astype(object)
    t0 = time.perf_counter()
    ids, n = label_cells(g)
    ids_s, n_s = label_cells(s, connectivity="full")
    elapsed = time.perf_counter() - t0
    assert len(np.unique(g)) > 9_000
    assert n >= len(np.unique(g)) and n_s >= len(np.unique(g))
    assert ids.min() == 1 and ids.max() == n
    assert elapsed < 2.0


def test_label_cells_all_excluded_and_single_node():
    g = np.full((3, 4), -1)
    ids, n = label_cells(g, exclude=(-1,))
    assert n == 0 and not ids.any()
    ids, n = label_cells(np.array([[5]]))
    assert n == 1 and ids.tolist() == [[1]]


# -- the statistics of a map's cells (studies a and l) ---------------------------------------------------


def test_cell_stats_of_a_known_map():
    """Four quadrants of two labels (two cells each: 100 nodes) and one singleton inside a quadrant."""
    from dicetrace.analysis.cells import cell_stats

    g = np.ones((20, 20), dtype=np.int64)
    g[:10, 10:] = 2
    g[10:, :10] = 2
    g[5, 5] = 3  # a singleton, away from the edge
    st = cell_stats(g)
    assert st["n_cells"] == 5 and st["n_nodes"] == 400 and st["n_singletons"] == 1
    assert sorted(st["sizes"].tolist()) == [1, 99, 100, 100, 100]
    assert st["frac_nodes_in_singletons"] == pytest.approx(1 / 400)
    assert st["largest_cell_frac"] == pytest.approx(0.25) and st["n_cells_ge_100"] == 3
    assert st["frac_nodes_in_edge_cells"] == pytest.approx(399 / 400)  # all but the singleton
    assert st["cells_per_1000_nodes"] == pytest.approx(12.5)


def test_block_fraction_stderr_is_zero_for_a_uniform_spread_and_grows_with_clumping():
    from dicetrace.analysis.cells import block_fraction_stderr

    stripes = np.tile(np.array([1, 2]), (40, 20))  # every block holds half of each label
    assert block_fraction_stderr(stripes, 1) == 0.0
    halves = np.ones((40, 40), dtype=np.int64)
    halves[:, 20:] = 2  # blocks are all 1 or all 2: fractions 1,1,0,0 in each row of blocks
    assert block_fraction_stderr(halves, 1) == pytest.approx(np.std([1, 1, 0, 0] * 4, ddof=1) / 4)


def test_slice_joins_tells_a_tube_from_separate_cells():
    """Two 2-D cells of slice 0 joined by a tube through z are one 3-D cell; two columns are two."""
    from dicetrace.analysis.cells import slice_joins

    g = np.ones((12, 12, 4), dtype=np.int64)
    g[2:5, 2:5, :] = 2
    g[7:10, 7:10, :] = 2
    apart = slice_joins(g, 5)
    assert apart["frac_cells_joined"] == 0.0 and apart["n_cells_2d"] == 3
    g[2:10, 2:10, 3] = 2  # a bridge in the top layer joins the two columns
    joined = slice_joins(g, 5)
    assert joined["frac_cells_joined"] == pytest.approx(2 / 3)  # the two label-2 cells; the label-1 cell is alone
    assert {r["label"]: r["components_3d"] for r in joined["per_label"]} == {1: 1, 2: 1}
    assert "half_res" not in joined  # 4 nodes in z: too few for the half-resolution check
