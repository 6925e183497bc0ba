"""Boundaries: dimension, basin entropy, and α where it checks them (α itself: test_uncertainty.py; Wada: test_wada.py).

Known answers:
- straight boundary: alpha = 1, D = 1 (Grebogi, McDonald, Ott & Yorke 1983);
- triadic escape basins (x -> 3x mod 1): boundary C x R, D = 1 + ln2/ln3,
  alpha = 1 - ln2/ln3 (McDonald et al. 1985, Physica D 17:125);
- Weierstrass graph: D = s (Kaplan, Mallet-Paret & Yorke 1984);
- Newton z**3 - 1 on [-1, 1]**2: D = 1.42, alpha ~ 0.6 (Attractors.jl test
  suite, test/basins/uncertainty_tests.jl, band 0.55 <= alpha <= 0.65).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from analysis_synthetic import (
    line_classify,
    newton_classify,
    sample_grid,
    weierstrass,
    weierstrass_classify,
)
from dicetrace.analysis import (
    basin_entropy,
    boundary_box_fraction,
    boundary_dimension,
    boundary_fraction,
    boundary_mask,
    box_counting_dimension,
    fit_power_law,
    uncertainty_exponent,
)

UNIT = [(0.0, 1.0), (0.0, 1.0)]
LN2_LN3 = math.log(2) / math.log(3)


def _weierstrass_grid(s, n=512):
    w = weierstrass(np.linspace(0, 2 * np.pi, 20001), s=s)
    ext = [(0.0, 2 * np.pi), (w.min() - 0.01, w.max() + 0.01)]
    return sample_grid(lambda p: weierstrass_classify(p, s=s), ext, (n, n))


def test_boundary_mask_exact():
    g = np.array([[1, 1, 2], [1, 1, 2], [3, 1, 2]])
    expected = np.array([[0, 1, 1], [1, 1, 1], [1, 1, 1]], dtype=bool)
    np.testing.assert_array_equal(boundary_mask(g), expected)
    # a change across a diagonal only: boundary for "full", not for "face"
    d = np.array([[1, 1, 1], [1, 1, 1], [1, 1, 2]])
    assert not boundary_mask(d)[1, 1] and boundary_mask(d, connectivity="full")[1, 1]
    assert boundary_fraction(np.ones((4, 4))) == 0.0
    assert boundary_box_fraction(np.ones((9, 9)), 2) == 0.0


def test_fit_power_law_exact():
    x = np.geomspace(1e-3, 1, 7)
    fit = fit_power_law(x, 3.0 * x**0.7)
    assert fit.slope == pytest.approx(0.7, abs=1e-12)
    assert fit.intercept == pytest.approx(math.log(3.0), abs=1e-12)


def test_newton_basins_alpha_and_dimension(newton_grid):
    # Attractors.jl band for this very grid (300 x 300 on [-1, 1]^2, box sizes 5..30)
    ue = uncertainty_exponent(newton_grid, box_sizes=range(5, 31))
    assert 0.55 <= ue.alpha <= 0.65
    # box counting of the boundary nodes vs the published D = 1.42: same
    # half-width (0.05) as the Attractors.jl alpha band.
    D = boundary_dimension(newton_grid, box_sizes=range(2, 16), method="mask").dimension
    assert D == pytest.approx(1.42, abs=0.05)


def test_weierstrass_boundary_dimension():
    # D = s for the Weierstrass graph. At 512^2 box counting is biased low
    # (the graph spans only a few of the largest boxes vertically; measured
    # +0.02, -0.06, -0.13 for s = 1.3, 1.5, 1.7, growing with s): tolerance
    # 0.1 at s = 1.5, 0.15 for all, and D must rise with s.
    dims = {}
    for s in (1.3, 1.5, 1.7):
        g = _weierstrass_grid(s)
        dims[s] = box_counting_dimension(boundary_mask(g), box_sizes=range(2, 17)).dimension
    assert dims[1.5] == pytest.approx(1.5, abs=0.1)
    assert dims[1.3] < dims[1.5] < dims[1.7]
    assert all(abs(d - s) < 0.15 for s, d in dims.items())


def test_basin_entropy_straight_boundaries_exact():
    # Vertical boundaries crossing the boxes of side b at every offset k = 1..b-1:
    # each boundary box has p = k/b, so Sbb = mean_k H(k/b) exactly
    # (-> 1/2 as b -> infinity, Daza et al. 2016) and Sbb < ln 2.
    b = 10
    rows = []
    for k in range(1, b):
        block = np.ones((3 * b, b), dtype=np.int64)
        block[b + k :, :] = 2
        rows.append(block)
    g = np.concatenate(rows, axis=1)
    be = basin_entropy(g, b)
    H = [-(k / b) * math.log(k / b) - (1 - k / b) * math.log(1 - k / b) for k in range(1, b)]
    assert be.Sbb == pytest.approx(np.mean(H), abs=1e-12)
    assert be.n_boundary_boxes == b - 1
    assert be.Sb == pytest.approx(np.mean(H) * (b - 1) / be.n_boxes, abs=1e-12)
    assert not be.fractal_boundary
    assert basin_entropy(np.ones((20, 20)), 5).Sb == 0.0


def test_basin_entropy_newton_is_fractal():
    # Daza et al. (2016) log-2 criterion: Sbb > ln 2 proves a fractal boundary.
    # Newton z^3 - 1 on [-0.5, 0.5]^2 (three basins meet densely), boxes of 5:
    # measured Sbb = 0.725; bound above by ln 3 (three labels).
    g = sample_grid(newton_classify, [(-0.5, 0.5), (-0.5, 0.5)], (300, 300))
    be = basin_entropy(g, 5)
    assert be.fractal_boundary
    assert math.log(2) < be.Sbb < math.log(3)
    # the straight line never passes the criterion
    line = sample_grid(line_classify, UNIT, (300, 300))
    assert basin_entropy(line, 5).Sbb < math.log(2)


def test_box_size_counts_nodes_in_every_function():
    """A box of b nodes a side everywhere (Attractors.jl's meaning): closed boxes of 2 nodes are
    the 2x2 windows, so on a 9x9 grid with one straight change 8 of the 64 hold two labels."""
    from dicetrace.analysis.boundaries import _default_box_sizes

    g = np.ones((9, 9), int)
    g[:, 5:] = 2
    assert boundary_box_fraction(g, 2) == 8 / 64
    assert boundary_box_fraction(g, 3) == 4 / 16  # 3x3 windows at stride 2: 4x4 boxes, one column of them cut
    with pytest.raises(ValueError, match="box_size"):
        boundary_box_fraction(g, 1)
    ue = uncertainty_exponent(g, box_sizes=[2, 3, 5], spacing=0.5)
    np.testing.assert_allclose(ue.eps, [0.5, 1.0, 2.0])  # a closed box of b nodes spans b - 1 spacings
    assert basin_entropy(g, 3).n_boxes == 9
    assert box_counting_dimension(g == 2, box_sizes=[3, 2]).counts.tolist() == [6, 8]  # disjoint boxes of b nodes
    sizes = _default_box_sizes((4000, 4000))
    assert sizes[0] == 2 and sizes[-1] == 200 and len(sizes) <= 12 and np.all(np.diff(sizes) > 0)
