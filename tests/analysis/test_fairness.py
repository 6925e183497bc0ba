"""Baseline models of a die's face probabilities and the statistics that hold them to data (dicetrace.analysis.fairness)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, stats

from dicetrace.analysis import fairness as f
from dicetrace.analysis.dice_data import GAZETTE_97_16, MeasuredCuboids
from dicetrace.analysis.grouping import wilson_interval
from dicetrace.core.model import FACE_OF_TOP4
from dicetrace.params import NODE_SIGNS

RNG_BOXES = [((1.0, 1.0, 1.0), (0.0, 0.0, 0.0)), ((1.0, 1.3, 0.6), (0.1, -0.2, 0.05)),
             ((0.5, 2.0, 1.0), (-0.3, 1.2, 0.7)), ((1.0, 1.0, 1.0), (0.0, 0.0, 0.95))]


def test_face_axes_are_the_face_table_of_the_simulator():
    for face, (axis, sign) in enumerate(f.FACE_AXES, start=1):
        nodes = np.flatnonzero(NODE_SIGNS[:, axis] * sign > 0)
        assert FACE_OF_TOP4[sum(1 << int(k) for k in nodes)] == face


# -- solid angle --------------------------------------------------------------------------------------


def test_solid_angle_of_a_cube_is_a_sixth_and_of_any_box_sums_to_one():
    np.testing.assert_allclose(f.solid_angle_faces((1, 1, 1)), 1 / 6, rtol=1e-15)
    for half, com in RNG_BOXES:
        assert f.solid_angle_faces(half, com).sum() == pytest.approx(1.0, abs=1e-14)  # Gauss: 4π around any point


@pytest.mark.parametrize("half, com", RNG_BOXES[1:])
def test_solid_angle_against_quadrature(half, com):
    """Each face's Ω against ∫ h/ρ³ dA over the face, seen from the (offset) centre of mass."""
    h, c = np.asarray(half), np.asarray(com)
    got = f.solid_angle_faces(half, com)
    for face, (axis, sign) in enumerate(f.FACE_AXES, start=1):
        u, v = [ax for ax in range(3) if ax != axis]
        dist = h[axis] - sign * c[axis]
        omega, _ = integrate.dblquad(lambda y, x: dist / (x * x + y * y + dist * dist) ** 1.5,
                                     -h[u] - c[u], h[u] - c[u], -h[v] - c[v], h[v] - c[v], epsabs=1e-13, epsrel=1e-12)
        assert got[6 - face] == pytest.approx(omega / (4 * math.pi), rel=1e-9)  # face f rests: 7 - f is up


def test_solid_angle_of_a_loaded_die_favours_the_face_away_from_the_load():
    p = f.solid_angle_faces((1, 1, 1), (0, 0, 0.3))  # load toward face 4 (+z): the die rests on 4 more, shows 3
    assert p[2] > 1 / 6 > p[3]
    assert p[0] == pytest.approx(p[1]) == pytest.approx(p[4]) == pytest.approx(p[5])


def test_square_cuboid_solid_angle_formula_and_limits():
    r = np.array([0.3, 0.47, 1.0, 1.6, 2.65])
    boxes = np.array([f.solid_angle_faces((1.0, 1.0, x)) for x in r])  # y = 2, x = 2·(x/y): square faces 3, 4
    np.testing.assert_allclose(f.solid_angle_p(r), boxes[:, 2] + boxes[:, 3], rtol=1e-13)
    assert f.solid_angle_p(1.0) == pytest.approx(1 / 3, rel=1e-15)
    assert 1 - f.solid_angle_p(1e-6) == pytest.approx(2 * math.sqrt(2) / math.pi * 1e-6, rel=1e-5)
    assert f.solid_angle_p(1e3) == pytest.approx(2 / math.pi / 1e6, rel=1e-5)
    assert np.all(np.diff(f.solid_angle_p(np.linspace(0.1, 5, 100))) < 0)


# -- the Gazette note's edge landing, step 1 -------------------------------------------------------------


@pytest.mark.parametrize("r", [0.47, 1.0, 1.6, 2.65])
def test_edge_tip_share_from_the_tipping_geometry(r):
    """Section across a y-edge: rotate the x×y rectangle by θ and see on which side of the edge its centre falls."""
    theta = (np.arange(200_000) + 0.5) / 200_000 * (math.pi / 2)  # θ uniform on [0, π/2]
    y, x = 1.0, r
    along_square = np.stack([np.cos(theta), np.sin(theta)])
    along_other = np.stack([-np.sin(theta), np.cos(theta)])
    centre = y / 2 * along_square + x / 2 * along_other
    share = np.mean(centre[0] > 0)  # beyond the vertical on the square face's side: it falls onto that face
    assert share == pytest.approx(f.edge_tip_square_share(r), abs=1e-5)


def test_edge_tip_limits():
    assert f.edge_tip_square_share(1.0) == pytest.approx(0.5, rel=1e-15)
    assert f.edge_tip_p(1.0) == pytest.approx(1 / 3, rel=1e-15)
    assert f.edge_tip_p(1e-9) == pytest.approx(2 / 3, rel=1e-8)
    assert f.edge_tip_p(1e9) == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="y_edge_share"):
        f.edge_tip_p(1.0, y_edge_share=1.5)


# -- Gibbs ---------------------------------------------------------------------------------------------


def test_gibbs_cube_and_limits():
    for lam in (1e-3, 0.1, 10.0):
        np.testing.assert_allclose(f.gibbs_faces((1, 1, 1), lam), 1 / 6, rtol=1e-14)
        assert f.gibbs_p(1.0, lam) == pytest.approx(1 / 3, rel=1e-14)
    np.testing.assert_allclose(f.gibbs_faces((0.5, 1.0, 2.0), 1e9), 1 / 6, rtol=1e-8)
    assert f.gibbs_p(1e-12, 0.2) == pytest.approx(1 / (1 + 2 * math.exp(-1 / 0.4)), rel=1e-10)
    assert f.gibbs_p(50.0, 0.1) < 1e-100 and f.gibbs_p(1e3, 0.1) == 0.0  # no overflow warning either
    # the lowest resting states only, as λ → 0: a flat tile (x < y) lies on a square face
    assert f.gibbs_p(0.5, 1e-4) == pytest.approx(1.0, abs=1e-12)


def test_gibbs_square_cuboid_is_the_box_model():
    for r in (0.47, 1.23, 2.65):
        for t in (0.05, 0.12, 1.0):
            box = f.gibbs_faces((0.5, 0.5, r / 2), t)  # y = 1: half-extents 0.5, 0.5 and x/2 along z
            assert f.gibbs_p(r, t) == pytest.approx(box[2] + box[3], rel=1e-13)


def test_gibbs_loaded_die():
    p = f.gibbs_faces((1, 1, 1), 0.1, (0, 0, -0.05))  # centre of mass 0.05 toward face 3: resting on 3 is lowest
    assert p.sum() == pytest.approx(1.0, abs=1e-15)
    assert p[3] == pytest.approx(p[2] * math.exp(0.1 / 0.1), rel=1e-13)  # heights 0.95 and 1.05
    assert p[3] > 1 / 6 > p[2]


# -- Pender & Uhrin ------------------------------------------------------------------------------------


def test_pender_uhrin_symmetries_and_limits():
    assert f.pender_uhrin_ratio(1.0, 1.0) == pytest.approx(1.0, rel=1e-15)
    for k, l in ((2.0, 1.0), (1.0, 3.0), (5.0, 4.0)):
        assert f.pender_uhrin_ratio(k, l) * f.pender_uhrin_ratio(l, k) == pytest.approx(1.0, rel=1e-14)
        assert f.pender_uhrin_ratio(7 * k, 7 * l) == pytest.approx(f.pender_uhrin_ratio(k, l), rel=1e-14)
        assert (f.pender_uhrin_ratio(k, l) < 1) == (k > l)  # the wide side is the likelier rest
        assert f.pender_uhrin_p(k, l) + f.pender_uhrin_p(l, k) == pytest.approx(1.0, rel=1e-14)
    k = 1e3
    assert f.pender_uhrin_ratio(k, 1.0) == pytest.approx(k**-3 / math.pi, rel=3e-3)


def test_pender_uhrin_is_barrier_times_basin():
    """The formula equals the ratio of (energy barrier to the corner)·(tilt to the corner) of the two rest states."""
    for k, l in ((2.0, 1.0), (1.5, 1.0), (3.0, 0.7)):
        diag = math.hypot(k, l) / 2

        def weight(side, other):  # resting on `side`: centre at other/2, tips over a corner after arctan(side/other)
            return (diag - other / 2) * math.atan(side / other)

        assert f.pender_uhrin_ratio(k, l) == pytest.approx(weight(l, k) / weight(k, l), rel=1e-14)


# -- models against the Gazette table (golden values of the comparison) ---------------------------------


def test_baselines_against_the_gazette_table():
    r = GAZETTE_97_16.aspect
    solid = f.compare(f.solid_angle_p(r))
    edge = f.compare(f.edge_tip_p(r))
    assert solid.dof == edge.dof == 15
    assert solid.chi2 == pytest.approx(1054.3205, rel=1e-6)
    assert edge.chi2 == pytest.approx(1784.0048, rel=1e-6)
    fit = f.fit_one_parameter(f.gibbs_p, (1e-3, 10.0), fit_points=r, log_scale=True)
    assert fit.value == pytest.approx(0.118676, rel=1e-4)
    assert fit.overall.chi2 == pytest.approx(100.7133, rel=1e-4) and fit.overall.dof == 14
    assert fit.interval[0] < fit.value < fit.interval[1]
    assert fit.predicted is None


# -- statistics -----------------------------------------------------------------------------------------


def _synthetic(p_true, n, counts, aspect=None):
    aspect = np.arange(1, len(n) + 1) * 0.5 if aspect is None else aspect
    return MeasuredCuboids(aspect=aspect, p=np.asarray(counts) / np.asarray(n), n=n, source="synthetic")


def test_compare_is_pearsons_chi2_of_the_counts():
    n = np.array([300, 1000, 50])
    k = np.array([120, 333, 4])
    model = np.array([0.37, 0.31, 0.1])
    data = _synthetic(model, n, k)
    got = f.compare(model, data)
    pearson = sum(stats.chisquare([kk, nn - kk], [nn * pp, nn * (1 - pp)]).statistic for kk, nn, pp in zip(k, n, model))
    assert got.chi2 == pytest.approx(pearson, rel=1e-12)
    assert got.p_value == pytest.approx(stats.chi2.sf(pearson, 3), rel=1e-12)
    # a Monte-Carlo model is a second binomial sample: Pearson's χ² of each 2×2 table of counts (no continuity
    # correction), finite where the model's share is 0
    mc = f.compare(model, data, model_n=4000)
    tables = [[[kk, nn - kk], [4000 * pp, 4000 * (1 - pp)]] for kk, nn, pp in zip(k, n, model)]
    two_by_two = [stats.chi2_contingency(t, correction=False).statistic for t in tables]
    np.testing.assert_allclose(mc.z ** 2, two_by_two, rtol=1e-12)
    assert np.sign(mc.z[0]) == np.sign(k[0] / n[0] - 0.37)
    zero = f.compare(np.array([0.0, 0.31, 0.1]), data, model_n=200)
    assert np.isfinite(zero.z).all() and zero.z[0] > 5
    only = f.compare(model, data, points=[1.0, 1.5], n_fitted=1)
    assert only.dof == 1 and list(only.aspect) == [1.0, 1.5]


def test_compare_edge_cases():
    data = _synthetic(None, np.array([100, 100]), np.array([0, 10]))
    c = f.compare(np.array([0.0, 0.0]), data)
    assert c.z[0] == 0.0 and c.z[1] == math.inf
    with pytest.raises(ValueError, match="x/y = 0.7"):
        f.compare(np.array([0.1, 0.1]), data, points=[0.7])
    with pytest.raises(ValueError, match="in \\[0, 1\\]"):
        f.compare(np.array([1.2, 0.1]), data)


def test_fit_one_parameter_recovers_a_known_parameter_and_predicts_the_rest():
    r = GAZETTE_97_16.aspect
    n = np.full(r.size, 10**6)
    exact = MeasuredCuboids(aspect=r, p=f.gibbs_p(r, 0.2), n=n, source="synthetic")
    fit = f.fit_one_parameter(f.gibbs_p, (0.01, 5.0), fit_points=[0.63, 0.93, 1.44], data=exact, log_scale=True)
    assert fit.value == pytest.approx(0.2, rel=1e-8)
    assert fit.on_fit.chi2 < 1e-8 and fit.on_fit.dof == 2
    assert fit.predicted.dof == 12 and fit.predicted.chi2 < 1e-8
    assert 0.0 not in fit.predicted.aspect and 0.63 not in fit.predicted.aspect
    lo, hi = fit.interval
    assert lo < 0.2 < hi and hi - lo < 1e-2  # 10⁶ throws a point pin λ down
    # χ² on the fit points rises by 1 at the ends of the interval
    for end in (lo, hi):
        assert f.compare(f.gibbs_p(r, end), exact, points=fit.fit_points).chi2 == pytest.approx(1.0, abs=1e-6)


def test_fit_one_parameter_names_bad_points():
    with pytest.raises(ValueError, match="x/y = 3.0"):
        f.fit_one_parameter(f.gibbs_p, (0.01, 1.0), fit_points=[0.47, 3.0])
    with pytest.raises(ValueError, match="bounds"):
        f.fit_one_parameter(f.gibbs_p, (1.0, 0.01), fit_points=[0.47])


def test_wilson_interval_is_scipys():
    for k, n in ((0, 10), (1, 29), (81, 263), (150, 1011), (3, 503), (503, 503), (16_667, 100_000)):
        ci = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
        assert wilson_interval(k, n) == pytest.approx((ci.low, ci.high), abs=1e-12)


def test_throws_to_detect_chi2_matches_cohens_table():
    """Cohen (1988, 1992): χ² test, 1 df, α = 0.05, power 0.80, effect w = 0.1 needs N = 785."""
    plan = f.throws_to_detect([0.55, 0.45], [0.5, 0.5], test="chi2", power=0.80)
    assert plan.effect == pytest.approx(0.1, rel=1e-12)
    assert plan.n == 785 and plan.power_at_n >= 0.80


def test_throws_to_detect_chi2_is_the_smallest_n():
    p = np.array([0.2] + [0.16] * 5)
    plan = f.throws_to_detect(p)
    crit = stats.chi2.isf(0.05, 5)
    w2 = plan.effect**2
    assert stats.ncx2.sf(crit, 5, plan.n * w2) >= 0.95 > stats.ncx2.sf(crit, 5, (plan.n - 1) * w2)


def _exact_power(n, p0, p1, alpha, upper):
    pmf0 = [math.comb(n, x) * p0**x * (1 - p0) ** (n - x) for x in range(n + 1)]
    pmf1 = [math.comb(n, x) * p1**x * (1 - p1) ** (n - x) for x in range(n + 1)]
    if upper:
        tail = 0.0
        c = n + 1
        while c > 0 and tail + pmf0[c - 1] <= alpha:
            c -= 1
            tail += pmf0[c]
        return sum(pmf1[c:])
    tail, c = 0.0, -1
    while c < n and tail + pmf0[c + 1] <= alpha:
        c += 1
        tail += pmf0[c]
    return sum(pmf1[: c + 1])


@pytest.mark.parametrize("p1", [1 / 3, 0.25, 0.05])
def test_throws_to_detect_binomial_against_enumeration(p1):
    p = np.full(6, (1 - p1) / 5)
    p[0] = p1
    plan = f.throws_to_detect(p, test="binomial", face=1, power=0.9)
    upper = p1 > 1 / 6
    powers = [_exact_power(n, 1 / 6, p1, 0.05, upper) for n in range(1, plan.n + 1)]
    assert powers[-1] == pytest.approx(plan.power_at_n, rel=1e-9)
    assert powers[-1] >= 0.9 and max(powers[:-1]) < 0.9  # the smallest such n


def test_throws_to_detect_binomial_near_the_normal_approximation():
    p0, p1 = 1 / 6, 0.18
    p = np.full(6, (1 - p1) / 5)
    p[2] = p1
    plan = f.throws_to_detect(p, test="binomial")
    assert plan.face == 3 and plan.effect == pytest.approx(p1 - p0)
    z_a, z_b = stats.norm.isf(0.05), stats.norm.isf(0.05)
    approx = ((z_a * math.sqrt(p0 * (1 - p0)) + z_b * math.sqrt(p1 * (1 - p1))) / (p1 - p0)) ** 2
    assert plan.n == pytest.approx(approx, rel=0.02)


def test_throws_to_detect_refuses_no_bias_and_bad_input():
    with pytest.raises(ValueError, match="no bias"):
        f.throws_to_detect(np.full(6, 1 / 6))
    with pytest.raises(ValueError, match="sums to 1"):
        f.throws_to_detect([0.5, 0.6])
    with pytest.raises(ValueError, match="test must be"):
        f.throws_to_detect([0.6, 0.4], test="t")


def test_dispersion_is_one_for_binomial_counts_and_phi_for_overdispersed_ones():
    # counts drawn about a known smooth curve: binomial scatter gives φ ≈ 1, a beta-binomial one of known φ gives φ
    rng = np.random.default_rng(7)
    aspect = np.geomspace(0.4, 2.8, 60)
    truth = 1 / (1 + np.exp(3.0 * np.log(aspect) + 0.4 * np.log(aspect) ** 2))  # logit p a quadratic in ln x/y
    n = np.full(60, 800)
    phis = []
    for _ in range(40):
        k = rng.binomial(n, truth)
        phis.append(f.dispersion(_synthetic(None, n, k, aspect=aspect), degree=2).phi)
    assert np.mean(phis) == pytest.approx(1.0, abs=0.06)  # E[χ²/dof] = 1; 40 draws of 57 dof: σ of the mean ≈ 0.03
    # beta-binomial with intra-class correlation ρ: variance n p (1-p) (1 + (n-1) ρ), so φ = 1 + (n - 1) ρ = 4
    rho = 3.0 / 799
    a_ = truth * (1 - rho) / rho
    b_ = (1 - truth) * (1 - rho) / rho
    phis = [f.dispersion(_synthetic(None, n, rng.binomial(n, rng.beta(a_, b_)), aspect=aspect), degree=2).phi
            for _ in range(40)]
    assert np.mean(phis) == pytest.approx(4.0, rel=0.1)
    # the fit is the binomial likelihood's maximum: the score vanishes, and an exact curve of that degree is recovered
    d = f.dispersion(_synthetic(None, n, n * truth, aspect=aspect), degree=2)
    np.testing.assert_allclose(d.p_curve, truth, rtol=1e-9)
    assert d.chi2 == pytest.approx(0.0, abs=1e-12) and d.dof == 57
    with pytest.raises(ValueError, match="degree"):
        f.dispersion(degree=14)


def test_compare_widens_only_the_datas_variance_by_the_dispersion():
    n = np.array([300, 1000, 50])
    k = np.array([120, 333, 4])
    model = np.array([0.37, 0.31, 0.1])
    data = _synthetic(model, n, k)
    exact, wide = f.compare(model, data), f.compare(model, data, dispersion=4.0)
    assert wide.chi2 == pytest.approx(exact.chi2 / 4.0, rel=1e-12)
    mc, mcw = f.compare(model, data, model_n=400), f.compare(model, data, model_n=400, dispersion=4.0)
    pooled = (n * k / n + 400 * model) / (n + 400)
    np.testing.assert_allclose(mcw.sigma ** 2, pooled * (1 - pooled) * (4.0 / n + 1 / 400), rtol=1e-12)
    assert mc.chi2 / 4.0 < mcw.chi2 < mc.chi2  # the simulation's own variance is not widened
    with pytest.raises(ValueError, match="dispersion"):
        f.compare(model, data, dispersion=0.0)
