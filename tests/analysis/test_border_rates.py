"""The near-border fit of the settle-time divergence (analysis.border_rates), on synthetic borders with known λ, and
the analytic edge saddle of each preset."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.analysis.border_rates import (Brackets, bisect_many, border_bootstrap, edge_saddle, end_flips,
                                             fit_sides, flat_range, line_crossings, local_slopes, profiles,
                                             tolerance_stability)
from dicetrace.analysis.settle import edge_balance_rate

LAM = 24.4
D_C = 1e-6  # where the approach term halves the local slope
DISTS = np.logspace(-11, -3, 33)


class Border:
    """A straight border x = x_b in the plane; T(d) = T0 − ln(d)/λ + ln(1 + d/d_c)/λ, quantised to 1 ms: the
    logarithmic law near the border, and an approach that is not linear farther out (the local slope
    dT/d(−ln d) = 1/(λ (1 + d/d_c)) falls below 1/λ), as at a border of the die."""

    def __init__(self, x_b: float = 0.0123456789, t_res: float = 1e-3):
        self.x_b, self.t_res, self.n = x_b, t_res, 0

    def classify(self, pts):
        pts = np.atleast_2d(pts)
        self.n += len(pts)
        return np.where(pts[:, 0] < self.x_b, 2, 5)

    def settle(self, pts):
        pts = np.atleast_2d(pts)
        d = np.abs(pts[:, 0] - self.x_b)
        t = 1.0 - np.log(d) / LAM + np.log1p(d / D_C) / LAM
        return self.classify(pts), np.round(t / self.t_res) * self.t_res


def _located(border, n=6, tol=1e-12):
    rng = np.random.default_rng(1)
    pairs = [(np.array([border.x_b - u, y]), np.array([border.x_b + v, y]))
             for u, v, y in rng.uniform(1e-4, 2e-3, (n, 3))]
    return bisect_many(border.classify, pairs, tol=tol)


def test_bisect_many_brackets_every_border_in_lockstep():
    # Known answer: the border is x = x_b; every bracket holds it, is shorter than tol, keeps the start's label at
    # its low end; one batch per halving: about log2(2e-3 / 1e-12) ≈ 31 halvings of 6 segments.
    b = Border()
    br = _located(b)
    assert np.all(br.p_lo[:, 0] < b.x_b) and np.all(br.p_hi[:, 0] >= b.x_b)
    assert np.all(br.width < 1e-12)
    assert set(br.label_lo) == {2} and set(br.label_hi) == {5}
    assert 6 * 25 < br.n_evals - 12 <= 6 * 32
    with pytest.raises(ValueError, match="same label"):
        bisect_many(b.classify, [(np.array([0.0, 0.0]), np.array([0.001, 0.0]))], tol=1e-12)


def test_near_border_fit_recovers_lambda_and_the_all_range_fit_is_biased_upward():
    # Known answer: λ = 24.4 /s.  The local slope is flat (within 2 %) only for d ≲ 0.02 d_c = 2e-8; the near-border
    # range ends there and its fits recover λ to 1 % (the 1 ms resolution of T); the fit over 1e-11 … 1e-3 sees the
    # approach term and is biased upward by more than 10 %, as the die's all-range fits are.
    b = Border()
    br = _located(b)
    prof = profiles(b.settle, br, DISTS)
    t = np.concatenate([prof["t_lo"], prof["t_hi"]])
    slopes, d_mid = local_slopes(DISTS, t, np.ones_like(t, bool), window=5)
    flat = flat_range(d_mid, slopes, rel=0.02)
    assert 1e-9 < flat["d_max"] and 1.0 / (1.0 + flat["d_max"] / D_C) > 0.97  # the true slope at its end: flat
    assert flat["reference_slope"] == pytest.approx(1 / LAM, rel=0.01)
    near = fit_sides(DISTS, br, prof, DISTS[0], flat["d_max"])
    whole = fit_sides(DISTS, br, prof, DISTS[0], DISTS[-1])
    assert np.median(near) == pytest.approx(LAM, rel=0.01)
    assert np.median(whole) > 1.1 * LAM


def test_local_slopes_of_the_pure_law_are_one_over_lambda():
    t = 0.7 - np.log(DISTS) / LAM
    s, d_mid = local_slopes(DISTS, t[None, :], np.ones((1, len(DISTS)), bool), window=5)
    assert np.allclose(s, 1 / LAM, rtol=1e-12)
    assert d_mid[0] == pytest.approx(DISTS[2], rel=1e-12)  # the geometric centre of the first five
    ok = np.ones((1, len(DISTS)), bool)
    ok[0, 7] = False
    s, _ = local_slopes(DISTS, t[None, :], ok, window=5)
    assert np.isnan(s[0, 3:8]).all() and np.isfinite(s[0, :3]).all() and np.isfinite(s[0, 8:]).all()


def test_fit_sides_drops_points_of_another_label():
    b = Border()
    br = _located(b, n=2)
    prof = profiles(b.settle, br, DISTS)
    prof["label_lo"][0, :] = 3  # the whole lo side of border 0 landed on another face
    lam = fit_sides(DISTS, br, prof, 1e-11, 1e-8)
    assert np.isnan(lam[0]) and np.isfinite(lam[1:]).all()


def test_tolerance_stability_starts_where_the_verdicts_stop_changing():
    b = Border()
    br = _located(b, n=3)
    prof = profiles(b.settle, br, DISTS)
    check = {k: v.copy() for k, v in prof.items()}
    check["label_hi"][1, :4] = 2  # the border moved by ~3e-11: the hi side's four nearest points change face
    check["t_lo"][0, 4:6] += 0.01  # a 10 ms change at d = 1e-10, 1.8e-10 on one side: the median stays 0
    st = tolerance_stability(DISTS, br, prof, check, t_res=1e-3)
    assert list(st["flips"][:5]) == [1, 1, 1, 1, 0] and st["d_min"] == pytest.approx(DISTS[4])
    check["t_lo"][:, 8] += 0.01  # every lo side 10 ms later at d = 1e-9: median |ΔT| above 1 ms there
    check["t_hi"][:, 8] += 0.01
    assert tolerance_stability(DISTS, br, prof, check, t_res=1e-3)["d_min"] == pytest.approx(DISTS[9])


def test_end_flips_counts_changed_verdicts():
    b = Border()
    br = _located(b, n=4)
    assert end_flips(b.classify, br)["n_changed"] == 0
    moved = Border(x_b=b.x_b + 1e-9)  # tightened numerics move the border past every bracket: the hi ends change
    f = end_flips(moved.classify, br)
    assert f["n_changed"] == 4 and f["fraction_changed"] == 0.5 and f["n_borders_moved"] == 4


def test_line_crossings_finds_neighbours_of_different_faces():
    b = Border(x_b=0.5)
    pairs = line_crossings(b.classify, np.array([[0.0, 0.1], [0.0, 0.9]]), np.array([[1.0, 0.2], [0.2, 0.9]]), 11)
    assert len(pairs) == 1  # the second line never reaches x = 0.5
    pa, pb = pairs[0]
    assert pa[0] < 0.5 <= pb[0] and pb[0] - pa[0] == pytest.approx(0.1)


def test_bootstrap_over_borders_resamples_both_sides_together():
    # Known answer: with both sides of a border equal, the median of 2n sides is that of n independent draws,
    # standard error √(π/2) σ/√n (asymptotic); n = 400, σ = 1: 0.0627, to 20 %.
    x = np.random.default_rng(5).normal(LAM, 1.0, 400)
    out = border_bootstrap(np.concatenate([x, x]), 400, n_boot=1000)
    assert out["median"] == pytest.approx(np.median(x))
    assert out["median_stderr"] == pytest.approx(math.sqrt(math.pi / 2) / 20, rel=0.2)
    assert out["n_sides"] == 800 and out["q25"] < out["median"] < out["q75"]


def test_edge_saddle_held_and_slipping_pivot():
    # seed: the program's friction (degree 0 in the velocities) holds the pivot: the rigid rate √(3g/(2√2 s)).
    s = edge_saddle(preset="seed")
    assert s.rate == pytest.approx(edge_balance_rate(), rel=1e-12) and s.rate == pytest.approx(22.797, abs=1e-3)
    assert s.rate_free == pytest.approx(math.sqrt(6 * 980 / (math.sqrt(2) * 2)), rel=1e-12)
    # physical: the viscous pivot (c = μ m g / v_reg = 940.8) slips; the cubic's positive root lies between the
    # held and the free pivot, and is the rate the linearised simulation gives (tests/analysis/test_edge.py: 24.427).
    p = edge_saddle(preset="physical")
    assert p.slip_c == pytest.approx(1.2 * 8 * 980 / 10)
    assert s.rate < p.rate < s.rate_free and p.rate == pytest.approx(24.427, abs=1e-3)
    i, m, r, g, c = p.inertia, 8.0, p.r, 980.0, p.slip_c
    assert i * m * p.rate**3 + (i + m * r * r) * c * p.rate**2 - m * m * g * r * p.rate - m * g * r * c == (
        pytest.approx(0.0, abs=1e-6 * m * g * r * c))
    # the limits: a very stiff viscous law holds the pivot, a very soft one frees it
    assert edge_saddle(preset="physical", v_reg_cm_s=1e-6).rate == pytest.approx(s.rate, rel=1e-4)
    assert edge_saddle(preset="physical", v_reg_cm_s=1e8).rate == pytest.approx(s.rate_free, rel=1e-4)


def test_brackets_unit_and_midpoint():
    br = Brackets(np.array([[0.0, 0.0]]), np.array([[3.0, 4.0]]), np.array([1]), np.array([2]), np.array([5.0]), 2)
    assert np.allclose(br.unit, [[0.6, 0.8]]) and np.allclose(br.midpoint, [[1.5, 2.0]])
