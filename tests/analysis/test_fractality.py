"""basins_fractal_test (Puy et al. 2021) on maps whose boundaries are known smooth or known fractal.

The band is Attractors.jl's (the smooth value of Puy et al.'s table 1, plus
the discrete-ball bias 0.224 eps**-1.006, plus or minus one standard error);
the smooth maps are straight lines at several angles, concentric circles and
a 1-D step series; the fractal ones are the Newton z**3 - 1 basins (whose
boundary is the Julia set, fractal at every scale, D = 1.42) and random
labels (a boundary everywhere).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from analysis_synthetic import newton_classify, sample_grid
from dicetrace.analysis import basin_entropy, basins_fractal_test, smooth_boundary_sbb

N = 700


def _stripes(angle_deg: float, n: int = N, period: float = 97.31) -> np.ndarray:
    """Parallel straight boundaries ``period`` nodes apart (a ball of radius <= 20 meets one at most)."""
    x, y = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    t = math.radians(angle_deg)
    return (np.floor((x * math.cos(t) + y * math.sin(t) + 0.37) / period) % 2).astype(np.int8)


@pytest.mark.parametrize("angle", [0, 17, 45])
@pytest.mark.parametrize("eps", [5, 10])
def test_straight_boundaries_are_smooth_at_the_reference_value(angle, eps):
    r = basins_fractal_test(_stripes(angle), eps=eps, rng=angle)
    assert r.verdict == "smooth" and not r.fractal, r
    assert r.smooth_Sbb == pytest.approx(0.4395093)
    assert r.band[0] <= r.Sbb <= r.band[1]
    assert r.n_balls == 1000 and r.n_tries >= r.n_balls


def test_a_fractional_radius_reaches_the_grid_edges_and_still_finds_straight_lines_smooth():
    """Balls of radius 2.5 on a grid only just wider than them touch both ends of every axis (their window once
    read past the last node: IndexError); at 7.5 straight boundaries are smooth as at whole radii."""
    rng = np.random.default_rng(1)
    small = rng.integers(0, 3, size=(8, 8))
    for seed in range(20):
        r = basins_fractal_test(small, eps=2.5, n_balls=100, rng=seed)
        assert 0 < r.Sbb <= math.log(3) + 1e-12
    r = basins_fractal_test(_stripes(17), eps=7.5, rng=5)
    assert r.verdict == "smooth" and r.band[0] <= r.Sbb <= r.band[1]


def test_circles_and_a_1d_step_are_smooth():
    x, y = np.meshgrid(np.arange(N), np.arange(N), indexing="ij")
    circles = (np.floor(np.hypot(x - 350.3, y - 350.7) / 83.1) % 2).astype(np.int8)
    assert basins_fractal_test(circles, eps=10).verdict == "smooth"
    steps = (np.floor(np.arange(20000) / 137.7) % 2).astype(int)
    r = basins_fractal_test(steps, eps=10)
    assert r.verdict == "smooth" and r.smooth_Sbb == pytest.approx(0.5, abs=1e-5)


@pytest.mark.parametrize("eps", [5, pytest.param(10, marks=pytest.mark.slow), pytest.param(20, marks=pytest.mark.slow)])
def test_newton_basins_are_fractal(eps):
    g = sample_grid(newton_classify, [(-1.0, 1.0), (-1.0, 1.0)], (N, N))
    r = basins_fractal_test(g, eps=eps)
    assert r.verdict == "fractal" and r.Sbb > r.band[1] + 0.1, r  # far above the smooth band (measured 0.65-0.72)
    assert r.Sbb < math.log(3)  # three basins at most in a ball


def test_random_labels_are_fractal_near_the_maximum_entropy():
    g = np.random.default_rng(1).integers(1, 4, (400, 400))
    r = basins_fractal_test(g, eps=5)
    assert r.verdict == "fractal" and r.Sbb == pytest.approx(math.log(3), abs=0.03)


@pytest.mark.slow  # about a second
def test_a_wider_confidence_widens_the_band_and_the_seed_reproduces():
    g = _stripes(30)
    a = basins_fractal_test(g, eps=10, rng=3)
    b = basins_fractal_test(g, eps=10, rng=3, confidence=0.95)
    assert a.Sbb == b.Sbb and a.n_tries == b.n_tries  # the same balls
    assert b.band[0] < a.band[0] and b.band[1] > a.band[1]
    assert b.band[1] - b.band[0] - b.bias == pytest.approx(1.96 / 1.0 * (a.band[1] - a.band[0] - a.bias), rel=1e-3)


def test_reference_values_by_dimension():
    assert [round(smooth_boundary_sbb(d), 4) for d in (1, 2, 3)] == [0.5, 0.4395, 0.3961]
    assert smooth_boundary_sbb(8) == pytest.approx(0.898 * 8**-0.4995)


@pytest.mark.parametrize(
    "grid, kwargs, match",
    [
        (np.ones((500, 500), int), {}, "met a boundary"),
        (np.ones((30, 30), int), {"eps": 20}, "too small"),
        (np.ones((500, 500), int), {"n_balls": 10}, "n_balls"),
        (np.ones((500, 500), int), {"eps": 0}, "eps"),
        (np.ones((500, 500), int), {"confidence": 1.0}, "confidence"),
    ],
)
def test_bad_input_is_refused_by_name(grid, kwargs, match):
    with pytest.raises(ValueError, match=match):
        basins_fractal_test(grid, max_tries=2000, **kwargs)


def test_basin_entropy_of_straight_lines_depends_on_their_angle():
    """The docstring's claim: Sbb -> 1/2 only for a boundary parallel to a box side; 45 degrees gives less."""
    flat = basin_entropy(_stripes(0, n=2000), 40).Sbb
    tilted = basin_entropy(_stripes(45, n=2000), 40).Sbb
    assert flat == pytest.approx(0.5, abs=0.03)
    assert 0.33 < tilted < 0.40
