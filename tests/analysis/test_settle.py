"""Settle time near borders: bisection, log-divergence fit, edge balance rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from analysis_synthetic import line_classify
from dicetrace.analysis import (
    ball_hill_saddle_rate,
    bisect_boundary,
    edge_balance_rate,
    fit_settle_divergence,
    settle_profile,
)

NORMAL = np.array([math.cos(0.3), math.sin(0.3)])
OFFSET = 0.6  # line_classify's default line: NORMAL . p = 0.6


def _settle_near_line(lam=22.8, t0=1.5):
    """Analytic settle-time function: T = T0 - ln(d) / lambda at normal distance d."""

    def settle(points):
        p = np.asarray(points, dtype=float)
        d = np.abs(p @ NORMAL - OFFSET)
        return line_classify(p), t0 - np.log(d) / lam

    return settle


def test_bisect_locates_line_to_tol():
    p_a, p_b = np.array([0.1, 0.5]), np.array([0.9, 0.45])
    br = bisect_boundary(line_classify, p_a, p_b, tol=1e-12)
    assert br.width < 1e-12
    assert (br.label_lo, br.label_hi) == (1, 2)
    # the exact crossing lies inside the bracket (up to round-off, 1e-15)
    s_lo, s_hi = br.p_lo @ NORMAL - OFFSET, br.p_hi @ NORMAL - OFFSET
    assert s_lo <= 1e-15 and s_hi >= -1e-15
    # bisection: ~log2(|p_b - p_a| / tol) + 2 evaluations
    assert br.n_evals <= math.ceil(math.log2(np.linalg.norm(p_b - p_a) / 1e-12)) + 3


def test_bisect_with_several_switches_reports_one_bracket():
    def stripes(points):
        return (np.floor(np.asarray(points)[:, 0] * 7) % 3).astype(int)  # labels 0, 1, 2

    br = bisect_boundary(stripes, [0.01, 0.0], [0.8, 0.0], tol=1e-10)  # 5 edges between
    assert br.label_lo != br.label_hi and br.width < 1e-10
    # the bracket sits on a stripe edge k/7
    x = br.midpoint[0] * 7
    assert abs(x - round(x)) < 1e-8
    with pytest.raises(ValueError):
        bisect_boundary(stripes, [0.01, 0.0], [0.02, 0.0])


def test_fit_exact_synthetic():
    d = np.geomspace(1e-12, 1e-3, 10)
    T = 2.0 - np.log(d) / 22.8
    fit = fit_settle_divergence(d, T)
    assert fit.lambda_per_s == pytest.approx(22.8, rel=1e-10)
    assert fit.t0_s == pytest.approx(2.0, rel=1e-10)


def test_fit_noisy_synthetic_within_stderr():
    # Gaussian noise of 5 ms: the estimate must fall within 4 standard errors
    # (fixed seed; 4 sigma keeps the test's false-alarm rate < 1e-4).
    rng = np.random.default_rng(7)
    d = np.geomspace(1e-12, 1e-3, 40)
    T = 2.0 - np.log(d) / 22.8 + rng.normal(0, 0.005, d.size)
    fit = fit_settle_divergence(d, T)
    assert abs(fit.lambda_per_s - 22.8) < 4 * fit.lambda_stderr
    assert fit.lambda_stderr < 0.5


def test_profile_and_fit_pipeline_recovers_lambda():
    settle = _settle_near_line(lam=22.8, t0=1.5)
    br = bisect_boundary(lambda p: settle(p)[0], [0.1, 0.5], [0.9, 0.45], tol=1e-14)
    prof = settle_profile(settle, br, np.geomspace(1e-10, 1e-3, 8))
    assert set(prof.side) == {"lo", "hi"}
    assert (prof[prof.side == "lo"].label == 1).all() and (prof[prof.side == "hi"].label == 2).all()
    fit = fit_settle_divergence(prof.d, prof.t_settle_s)
    # distance along the segment = normal distance / sin(angle): only T0 moves.
    # Tolerance 1e-3: the located point is off the line by < 1e-14, i.e.
    # 1e-4 relative at the smallest d = 1e-10.
    assert fit.lambda_per_s == pytest.approx(22.8, rel=1e-3)


def test_edge_balance_rate():
    # lambda = sqrt(3 g / (2 sqrt(2) s)) for a uniform cube of side s = 2 cm
    lam = edge_balance_rate()
    assert lam == pytest.approx(math.sqrt(3 * 980 / (2 * math.sqrt(2) * 2.0)), rel=1e-14)
    assert lam == pytest.approx(22.797, abs=1e-3)
    # with all the mass at the centre (I_cm = 0) the cube is a point mass on a
    # rod of length r = s / sqrt 2: the ball-hill saddle rate sqrt(g / r)
    assert edge_balance_rate(inertia_factor=0.0) == pytest.approx(
        ball_hill_saddle_rate(radius_cm=2 / math.sqrt(2)), rel=1e-14
    )
    # eight corner point masses: I_cm = (1/2) m s^2 -> I_edge = m s^2
    assert edge_balance_rate(inertia_factor=0.5) == pytest.approx(
        math.sqrt(980 * math.sqrt(2) / 4.0), rel=1e-14
    )


def test_settle_stats_border_and_interior():
    from types import SimpleNamespace

    from dicetrace.analysis.settle import settle_stats

    g = np.ones((20, 20), dtype=np.int64)
    g[:, 10:] = 2
    t = np.full(g.shape, 0.5)
    t[:, 9:11] = 1.5  # slow along the border
    s = SimpleNamespace(labels=g, t_settle_s=t)
    st = settle_stats(s)
    assert st["border_mean"] == pytest.approx(1.5) and st["interior_mean"] == pytest.approx(0.5)
    assert st["n_unsettled"] == 0 and st["median"] == pytest.approx(0.5) and st["max"] == pytest.approx(1.5)


# -- borders located and fitted, and their λ summarised (studies g, k and l) ------------------------------


def test_free_pivot_rate_is_twice_the_fixed_pivot_rate():
    """A cube on an edge: √(6g/(√2 s)) on a frictionless floor, √(3g/(2√2 s)) with the pivot held: ratio 2."""
    from dicetrace.analysis.settle import free_pivot_rate

    assert free_pivot_rate() == pytest.approx(2 * edge_balance_rate())
    assert free_pivot_rate() == pytest.approx(math.sqrt(6 * 980.0 / (math.sqrt(2) * 2.0)))


def test_border_pairs_are_neighbours_with_two_settled_outcomes():
    from types import SimpleNamespace

    from dicetrace.analysis.settle import border_pairs

    g = np.ones((6, 6), dtype=np.int64)
    g[:, 3:] = 2
    g[0, 3] = -1  # unsettled: no pair with it
    s = SimpleNamespace(labels=g, axes=(np.arange(6) * 0.1, np.arange(6) * 0.1))
    pairs = border_pairs(s, 100, np.random.default_rng(0))
    assert len(pairs) == 5
    assert all(a[0] == b[0] and b[1] - a[1] == pytest.approx(0.1) and a[1] == pytest.approx(0.2) for a, b in pairs)
    assert len(border_pairs(s, 2, np.random.default_rng(0))) == 2


def test_divergence_summary_and_lambdas():
    from dicetrace.analysis.settle import divergence_lambdas, divergence_summary

    fits = [{"lo": {"lambda": 20.0, "r": -0.999}, "hi": {"lambda": 24.0, "r": -0.99}},
            {"lo": None, "hi": {"lambda": 22.0, "r": -0.9999}}]
    s = divergence_summary(fits)
    assert s["n_fits"] == 3 and s["n_clean"] == 2 and s["median"] == 22.0
    assert s["clean_mean"] == pytest.approx(21.0) and s["clean_min"] == 20.0 and s["clean_max"] == 22.0
    assert s["median_stderr"] > 0
    lam = divergence_lambdas(fits)
    assert "all" not in lam and "r" not in lam and lam["n_borders"] == 2
    assert lam["lambdas"].tolist() == [20.0, 24.0, 22.0] and lam["mean"] == pytest.approx(22.0)
    assert lam["mean_stderr"] == pytest.approx(2.0 / math.sqrt(3))
