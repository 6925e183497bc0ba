"""The uncertainty exponent α (analysis.uncertainty) by boxes, by resolution and by perturbation, on known answers.

- straight boundary: alpha = 1 (Grebogi, McDonald, Ott & Yorke 1983), in 2-D and for a plane in 3-D;
- triadic escape basins (x -> 3x mod 1): alpha = 1 - ln2/ln3 (McDonald et al. 1985, Physica D 17:125);
- Weierstrass graph of Hölder exponent H = 2 - s: alpha = H under random-direction perturbation.
The Newton basins' alpha and the box sizes shared with the dimensions are in test_boundaries.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from analysis_synthetic import line_classify, sample_grid, triadic_classify, weierstrass_classify
from dicetrace.analysis import (
    basin_entropy,
    boundary_dimension,
    uncertainty_exponent,
    uncertainty_exponent_perturbation,
    uncertainty_exponent_resolution,
)

UNIT = [(0.0, 1.0), (0.0, 1.0)]
LN2_LN3 = math.log(2) / math.log(3)


@pytest.fixture(scope="module")
def line_grid():
    return sample_grid(line_classify, UNIT, (512, 512))


def test_straight_boundary_alpha_one(line_grid):
    # alpha = 1 exactly for a smooth boundary; tolerance 0.02 ~ 5x the
    # regression stderr (0.004) of the fit over box sizes 2..25.
    ue = uncertainty_exponent(line_grid, spacing=1 / 511)
    assert ue.alpha == pytest.approx(1.0, abs=0.02)
    assert ue.alpha_stderr < 0.01
    assert ue.dimension == pytest.approx(1.0, abs=0.02)
    assert boundary_dimension(line_grid).dimension == pytest.approx(1.0, abs=0.02)
    sub = uncertainty_exponent(line_grid, box_sizes=range(1, 9), method="subsample")
    assert sub.alpha == pytest.approx(1.0, abs=0.02)


def test_resolution_series_and_3d_plane():
    # f(h) = boundary-node fraction of scans at spacing h: a straight line gives
    # f ~ h^1; tolerance 0.03 (the node count across the line fluctuates by
    # +-1 per column at the coarsest grid, ~1%).
    ns = [64, 128, 256, 512]
    grids = [sample_grid(line_classify, UNIT, (n, n)) for n in ns]
    ue = uncertainty_exponent_resolution(grids, [1 / (n - 1) for n in ns])
    assert ue.alpha == pytest.approx(1.0, abs=0.03)
    # a tilted plane in a 3-D stack: alpha = 1, boundary dimension d - alpha = 2
    n3 = sample_grid(
        lambda p: np.where(p @ np.array([0.3, 0.5, 0.81]) > 0.8, 2, 1), [(0, 1)] * 3, (64, 64, 64)
    )
    ue3 = uncertainty_exponent(n3, box_sizes=range(2, 9))
    assert ue3.ndim == 3
    assert ue3.alpha == pytest.approx(1.0, abs=0.03)
    assert boundary_dimension(n3, box_sizes=range(2, 9)).dimension == pytest.approx(2.0, abs=0.03)
    be = basin_entropy(n3, 4)
    assert 0 < be.Sbb < math.log(2)


def test_straight_boundary_perturbation_alpha_one():
    # weighted fit over 3 decades; tolerance = 3 x stderr, about 0.06, covers
    # the binomial noise of 20000 pairs at the smallest eps (~13 changes).
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1, (20000, 2))
    ue = uncertainty_exponent_perturbation(line_classify, pts, np.geomspace(1e-4, 1e-1, 10), rng)
    assert abs(ue.alpha - 1.0) < max(3 * ue.alpha_stderr, 0.03)
    # f(eps) = (2/pi) eps L / A for random directions (E|n.u| = 2/pi), with
    # L = 1/cos(0.3) the length of the line across the unit square;
    # rel. tolerance 0.08 = 3 binomial sigma at f = 0.074, n = 20000.
    L = 1 / math.cos(0.3)
    assert ue.f[-1] == pytest.approx(2 / math.pi * 0.1 * L, rel=0.08)


def test_triadic_basins_perturbation_alpha():
    # exact alpha = 1 - ln2/ln3 = 0.3691; tolerance 0.03: the Cantor set's
    # log-periodic oscillation of f(eps) (lacunarity) moves fitted slopes over
    # 3 decades by ~0.01, plus 3 stderr (~0.005 each).
    rng = np.random.default_rng(1)
    pts = rng.uniform(0, 1, (20000, 2))
    ue = uncertainty_exponent_perturbation(triadic_classify, pts, np.geomspace(1e-5, 1e-2, 10), rng)
    assert ue.alpha == pytest.approx(1 - LN2_LN3, abs=0.03)
    assert ue.dimension == pytest.approx(1 + LN2_LN3, abs=0.03)


def test_weierstrass_perturbation_alpha():
    # random-direction perturbation of a Holder-H graph: alpha = H = 2 - s
    # (the horizontal component dominates); tolerance 0.06 = 3 x stderr + the
    # spread of 0.49..0.54 seen over seeds.
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(0, 2 * np.pi, 20000), rng.uniform(-1.7, 1.7, 20000)])
    ue = uncertainty_exponent_perturbation(weierstrass_classify, pts, np.geomspace(1e-5, 1e-2, 10), rng)
    assert ue.alpha == pytest.approx(0.5, abs=0.06)
