"""IC spaces: seed slices bit for bit, general and orthonormal slices, windows, grids, samples."""

from __future__ import annotations

import re

import numpy as np
import pytest

from dicetrace.ics import (
    SEED_DIRS_6D,
    SLICES,
    TOPOLOGY_POINTS,
    WINDOWS,
    Grid,
    Points,
    Sample,
    Slice,
    get_slice,
    get_window,
    grid_axis,
    seed_slice,
    space_from_dict,
)


def _bits(a):
    return np.asarray(a, dtype=np.float64).view(np.int64)


def test_seed_slice_by_hand():
    # L = x·(3.2612, 3.1314, 0.0606) + y·(2.1595, 4.5284, 3.9535) + (0, 100, 0); U = x·(...) + y·(...)
    x, y = 1.65, 3.9
    want = [x * 2.7083 + y * 2.4650, x * 3.4373 + y * 1.4853, x * 4.4365 + y * 0.6534,
            (x * 3.2612 + y * 2.1595) + 0.0, (x * 3.1314 + y * 4.5284) + 100.0, (x * 0.0606 + y * 3.9535) + 0.0]
    np.testing.assert_array_equal(_bits(seed_slice(x, y)), _bits(want))


def test_seed_slice_matches_the_program_points(reference_dir):
    import pandas as pd

    ref = pd.read_csv(reference_dir / "writeup_points.csv")
    ics = seed_slice(ref["x"].to_numpy(), ref["y"].to_numpy())
    np.testing.assert_array_equal(ics, ref[["vx", "vy", "vz", "Lx", "Ly", "Lz"]].to_numpy())


@pytest.mark.parametrize("name, z", [("seed", None), ("seed3", 0.37)])
def test_named_seed_slices_are_bit_identical_to_seed_slice(name, z):
    rng = np.random.default_rng(5)
    c = rng.uniform(-3, 30, size=(500, 2 if z is None else 3))
    got = get_slice(name).ics(c)
    want = seed_slice(c[:, 0], c[:, 1], None if z is None else c[:, 2])
    np.testing.assert_array_equal(_bits(got), _bits(want))


def test_general_slice_formula():
    sl = Slice("s", (1, 2, 3, 4, 5, 6), ((1, 0, 0, 0, 0, 0), (0, 0, 0, 0, 0, 2)))
    np.testing.assert_array_equal(sl.ics([0.5, 0.25]), [1.5, 2, 3, 4, 5, 6.5])
    one = Slice("line", (0, 0, 0, 0, 100, 0), ((1, 1, 1, 1, 1, 1),))
    assert one.ndim == 1
    np.testing.assert_array_equal(one.ics([[2.0]]), [[2, 2, 2, 2, 102, 2]])
    with pytest.raises(ValueError, match="linearly dependent"):
        Slice("bad", (0,) * 6, ((1, 0, 0, 0, 0, 0), (2, 0, 0, 0, 0, 0)))
    with pytest.raises(ValueError, match="1 to 3"):
        Slice("bad", (0,) * 6, ())
    with pytest.raises(ValueError, match="6 components"):
        Slice("bad", (0,) * 5, ((1, 0, 0, 0, 0, 0),))


@pytest.mark.parametrize("name, n", [("seed-ortho", 2), ("seed3-ortho", 3)])
def test_orthonormal_slices(name, n):
    sl = SLICES[name]
    d = np.array(sl.directions)
    np.testing.assert_allclose(d @ d.T, np.eye(n), atol=1e-14)
    # the same span, in the same order (Gram–Schmidt): direction k lies in span(seed 1..k)
    for k in range(n):
        basis = SEED_DIRS_6D[: k + 1]
        coef, res, *_ = np.linalg.lstsq(basis.T, d[k], rcond=None)
        np.testing.assert_allclose(basis.T @ coef, d[k], atol=1e-12)
    assert sl.origin == get_slice("seed").origin


def test_grid_formula_by_hand():
    # x = x0 + (p-1)/(n-1)·(x1-x0), p = 1..n, evaluated in that order
    xs = grid_axis(0.0, 0.1, 21)
    assert xs[0] == 0.0 and xs[20] == 0.1 and xs[10] == 0.05
    assert xs[1] == 0.005000000000000001  # (1/20)·0.1 rounds up: not 0.005
    # (7/20)·0.1 = 0.034999999999999996, where 7·0.1/20 or 0.1·7/20 would give 0.035
    assert xs[7] == 0.034999999999999996
    assert xs[16] == 0.08000000000000002
    ys = grid_axis(3.5, 4.5, 21)
    assert ys[8] == 3.9 and ys[10] == 4.0 and ys[18] == 4.4
    np.testing.assert_array_equal(grid_axis(2.0, 5.0, 1), [2.0])
    np.testing.assert_array_equal(grid_axis(-1.0, 1.0, 3), [-1.0, 0.0, 1.0])


def test_writeup_topology_points_lie_on_the_red_sea_grid():
    g = Grid("seed", "red-sea", 21)
    xs, ys = g.axes()
    for x, y in TOPOLOGY_POINTS:
        assert x in xs and y in ys


def test_grid_block_layout():
    g = Grid("seed3", ((0, 1), (0, 2), (0, 3)), (3, 4, 5))
    assert g.size == 60 and g.shape == (3, 4, 5)
    b = g.block(0, 60)
    i, j, k = b.index.T
    np.testing.assert_array_equal(b.ic_id, (i * 4 + j) * 5 + k)
    xs, ys, zs = g.axes()
    np.testing.assert_array_equal(b.coords, np.stack([xs[i], ys[j], zs[k]], axis=1))
    np.testing.assert_array_equal(b.ics, seed_slice(xs[i], ys[j], zs[k]))
    part = g.block(17, 33)
    np.testing.assert_array_equal(part.ics, b.ics[17:33])
    g2 = Grid("seed", "home", 5)
    b2 = g2.block(0, 25)
    assert (b2.index[:, 2] == 0).all() and np.isnan(b2.coords[:, 2]).all()
    with pytest.raises(ValueError):
        g2.block(20, 26)


def test_windows_by_name_and_by_numbers():
    # the writeup's eight windows are there (with the program's zooms and the studies' deep zooms)
    assert {"home", "zoom-out", "more-out", "most-out", "red-sea", "red-sea-2", "party", "green-island"} <= set(WINDOWS)
    assert get_window("red sea") == ((1.0, 2.0), (3.5, 4.5))
    assert get_window("Green_Island") == ((0.055, 0.06), (0.035, 0.045))
    assert get_window("0,0.1,0,0.2") == ((0.0, 0.1), (0.0, 0.2))
    assert get_window("home", 3, (0, 0.5)) == ((0.0, 0.1), (0.0, 0.1), (0.0, 0.5))
    with pytest.raises(ValueError, match="z range"):
        get_window("home", 3)
    with pytest.raises(ValueError, match="unknown window"):
        get_window("atlantis")
    with pytest.raises(ValueError):
        get_window("0,1,2")


def test_zoom_is_any_subwindow_at_any_resolution():
    coarse = Grid("seed", "red-sea", 21)
    fine = Grid("seed", ((1.4, 1.56), (3.95, 4.25)), (7, 13))
    assert fine.size == 91
    b = fine.block(0, fine.size)
    assert b.coords[:, 0].min() == 1.4 and b.coords[:, 0].max() == 1.56
    assert coarse.block(0, 1).coords[0, 0] == 1.0


@pytest.mark.parametrize("method", ["random", "sobol"])
def test_samples_do_not_depend_on_chunking(method):
    s = Sample("seed", ((0, 20), (0, 20)), 10000, method, seed=3)
    whole = s.block(0, s.size).coords
    parts = np.concatenate([s.block(a, b).coords for a, b in ((0, 1), (1, 4097), (4097, 5000), (5000, 10000))])
    np.testing.assert_array_equal(whole, parts)
    xy = whole[:, :2]
    assert (xy >= 0).all() and (xy <= 20).all()
    assert abs(xy.mean() - 10) < 0.3
    other = Sample("seed", ((0, 20), (0, 20)), 10000, method, seed=4).block(0, 10).coords
    assert not np.array_equal(other, whole[:10])


def test_sobol_is_more_uniform_than_random():
    def disc(method):
        c = Sample("seed", ((0, 1), (0, 1)), 4096, method, seed=1).block(0, 4096).coords[:, :2]
        h, *_ = np.histogram2d(c[:, 0], c[:, 1], bins=16, range=((0, 1), (0, 1)))
        return np.abs(h - 16).max()

    assert disc("sobol") < disc("random")


def test_points_and_dict_round_trip():
    p = Points("seed", [[1.65, 3.9], [1.5, 4.0]])
    np.testing.assert_array_equal(p.block(0, 2).ics, seed_slice([1.65, 1.5], [3.9, 4.0]))
    for space in (p, Grid("seed3-ortho", ((0, 1), (0, 1), (0, 1)), 4), Sample("seed", "home", 10, "sobol", 2)):
        assert space_from_dict(space.to_dict()) == space



# -- seed_slice's ICs carry their slice coordinates ----------------------------------------------


def test_seed_slice_ics_carry_their_coordinates():
    from dicetrace.ics import SliceICs

    x, y, z = np.array([1.0, 1.5, 2.0]), np.array([3.5, 4.0, 4.5]), np.array([0.1, 0.2, 0.3])
    a = seed_slice(x, y)
    assert isinstance(a, SliceICs) and isinstance(a, np.ndarray) and a.dtype == np.float64 and a.shape == (3, 6)
    np.testing.assert_array_equal(a.coords, np.column_stack([x, y, np.full(3, np.nan)]))
    np.testing.assert_array_equal(seed_slice(x, y, z).coords, np.column_stack([x, y, z]))
    one = seed_slice(1.65, 3.9)
    assert one.shape == (6,) and one.coords.tolist()[:2] == [1.65, 3.9] and np.isnan(one.coords[2])
    np.testing.assert_array_equal(seed_slice(1.0, y).coords[:, :2], np.column_stack([np.ones(3), y]))  # broadcast
    # the values are seed_slice's, bit for bit, whatever the container
    np.testing.assert_array_equal(_bits(a), _bits(np.asarray(a)))


def test_selecting_rows_keeps_coordinates_and_anything_else_drops_them():
    import pickle

    from dicetrace.ics import SliceICs

    x, y = np.linspace(1.0, 2.0, 5), np.linspace(3.5, 4.5, 5)
    a = seed_slice(x, y)
    for key, rows in [(slice(1, 4), [1, 2, 3]), ([4, 0], [4, 0]), (np.array([True, False, True, False, False]), [0, 2]),
                      ((slice(None, 2), slice(None)), [0, 1]), ((np.array([3]), Ellipsis), [3])]:
        got = a[key]
        assert isinstance(got, SliceICs) and got.coords[:, 0].tolist() == x[rows].tolist(), key
    assert a[2].coords[:2].tolist() == [x[2], y[2]] and a[-1].coords[0] == x[-1]
    assert a.copy().coords[:, 1].tolist() == y.tolist() and a.copy().coords is not a.coords
    back = pickle.loads(pickle.dumps(a))
    np.testing.assert_array_equal(back.coords, a.coords)
    # columns, reshapes and masks over components are not rows at those coordinates
    assert a[:, 3:].coords is None and a.reshape(-1).coords is None and a.T.coords is None
    assert getattr(a[a > 5], "coords", None) is None
    # arithmetic and other ufuncs give plain arrays; reductions give plain numbers
    for derived in (a * np.array([1, 1, 1, -1, -1, -1]), a + 0.0, np.abs(a), np.concatenate([a, a])):
        assert type(derived) is np.ndarray
    assert type(a.sum()) is np.float64 and type(a.max(axis=0)) is np.ndarray
    assert type(np.asarray(a)) is np.ndarray


@pytest.mark.parametrize("bad", [1 + 2j, np.array([1.0 + 0j]), True, "1.5", None, [1.0, "a"]], ids=repr)
def test_seed_slice_refuses_coordinates_that_are_not_real_numbers(bad):
    with pytest.raises(ValueError, match="seed_slice x must be real numbers"):
        seed_slice(bad, 3.9)


@pytest.mark.parametrize(
    "res, ndim, expected",
    [("8", 2, (8, 8)), (" 4, 3 ", 2, (4, 3)), ("2,3,1", 3, (2, 3, 1)), (5, 3, (5, 5, 5)), ((2.0, 3), 2, (2, 3)),
     (np.int64(6), 2, (6, 6)), ([7], 2, (7, 7))],
)
def test_get_res_is_the_one_reader_of_a_resolution(res, ndim, expected):
    from dicetrace.windows import get_res

    assert get_res(res, ndim) == expected
    assert Grid("seed3" if ndim == 3 else "seed", ((0, 1),) * ndim, res).res == expected  # Grid reads it so


@pytest.mark.parametrize(
    "res, words",
    [("2.5", "whole numbers, N or NX,NY, got '2.5'"), ("3,3,3", "needs 2 numbers NX,NY"), ("-3", ">= 1 on every axis"),
     ("", "whole numbers"), (True, "one integer per axis"), ((3, 0), ">= 1"), (2.5, "one integer per axis"), ("9" * 5000, "whole")],
)
def test_get_res_refuses_naming_res(res, words):
    from dicetrace.params import ConfigError
    from dicetrace.windows import get_res

    with pytest.raises(ConfigError, match=re.escape(words)) as exc:
        get_res(res, 2)
    assert exc.value.field == "res"


def test_get_window_names_the_z_range_apart_and_quotes_a_window_given_as_text():
    from dicetrace.params import ConfigError

    assert get_window("home", 3, "0,0.5") == ((0.0, 0.1), (0.0, 0.1), (0.0, 0.5))
    for window, z, field, words in (("home", "0.5,0", "z", "z1 > z0"), ("home", "0,x", "z", "two numbers"),
                                    ("home", None, "z", "needs a z range"), ("1,0,0,1", None, "window", "(got '1,0,0,1')"),
                                    ("atlantis", None, "window", "unknown window 'atlantis'")):
        with pytest.raises(ConfigError, match=re.escape(words)) as exc:
            get_window(window, 3 if z or field == "z" else 2, z)
        assert exc.value.field == field, (window, z)
