"""The hazard law's measures (:mod:`dicetrace.analysis.hazard_law`) on samples with known answers.

A synthetic die: each base point lies a distance d from a border along its ray, with P(d < ε) = f(ε) chosen (a
power law ε^α, or one whose exponent steps at a scale), and settles at t = T0 − ln d / λ.  Then the pair at scale ε
changes exactly where d < ε, the settle hazard at t is α(ε(t))·λ with ε(t) = exp(−λ (t − T0)), and the settle clock
of the bases changed at ε reads T0 + 1/(αλ) with slope 1/λ: every estimator has a number to hit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.analysis.hazard_law import (along_rays, eps_of_t, law_verdict, law_window, levels_off, log_depth,
                                           log_f_at, nested_f, quantile_hazard, secant_alpha, settle_clock, unit_rays)

QUANTILES = (0.5, 0.75, 0.9, 0.95, 0.97, 0.98, 0.99, 0.995, 0.998, 0.999, 0.9997)


def test_the_hazard_of_exponential_lifetimes_is_kappa_in_every_quantile_window():
    kappa = 20.0
    t = np.random.default_rng(1).exponential(1 / kappa, 200_000)
    hz, edges = quantile_hazard(t, QUANTILES)
    assert np.allclose(edges, -np.log(1 - np.array(QUANTILES)) / kappa, rtol=0.06)
    assert len(hz.h) == len(QUANTILES) - 1
    z = (hz.h - kappa) / hz.stderr
    assert np.all(np.abs(z) < 4), z
    assert np.all(np.abs(hz.stderr / hz.h - 1 / np.sqrt(hz.events)) < 1e-12)  # Poisson errors
    assert hz.events[-1] == pytest.approx(200_000 * (0.9997 - 0.999), rel=0.2)  # past the 99.9 % quantile
    # a wrong rate is told apart: the pooled tail rejects 1.1 κ
    tail = hz.events[2:].sum() / (hz.events[2:] / hz.h[2:]).sum()
    assert abs(tail - kappa) < 3 * kappa / math.sqrt(hz.events[2:].sum()) < 0.1 * kappa


def test_the_hazard_of_a_stepped_sample_finds_the_step_and_censoring_adds_no_event():
    # hazard 10 /s before t = 0.2 s, 40 /s after; a fifth of the sample censored at 0.3 s
    rng = np.random.default_rng(2)
    e = rng.exponential(1.0, 300_000)
    t = np.where(e < 10 * 0.2, e / 10, 0.2 + (e - 2.0) / 40)
    cen = rng.random(len(t)) < 0.2
    t = np.where(cen, np.minimum(t, 0.3), t)
    cen &= t >= 0.3
    hz, edges = quantile_hazard(t, QUANTILES, censored=cen)
    for h, se, a, b in zip(hz.h, hz.stderr, hz.t0, hz.t1):
        if b <= 0.2:
            assert abs(h - 10) < 4 * se
        elif a >= 0.2:
            assert abs(h - 40) < 4 * se
        else:  # the window holding the step lies between
            assert 10 < h < 40
    assert (hz.t1 <= 0.2).any() and (hz.t0 >= 0.2).any()
    assert hz.events.sum() == int(((t >= edges[0]) & (t < edges[-1]) & ~cen).sum())


def _synthetic_distances(n, rng, alpha=0.6, eps_k=None, alpha_fine=1.0):
    """Distances d with P(d < ε) = ε^alpha (ε ≤ 1), or, with ``eps_k``, ε^alpha above eps_k and
    eps_k^alpha (ε/eps_k)^alpha_fine below."""
    u = rng.random(n)
    if eps_k is None:
        return u ** (1 / alpha)
    fk = eps_k**alpha
    return np.where(u < fk, eps_k * (u / fk) ** (1 / alpha_fine), u ** (1 / alpha))


def _nested(d, eps):
    """Nested pairs of the synthetic die: the bases changed at the top, and their changes at every scale."""
    top = d < eps[-1]
    return d[top][:, None] < np.asarray(eps)[None, :]


def test_nested_f_of_a_power_law_has_local_slopes_alpha():
    rng = np.random.default_rng(3)
    n, alpha = 400_000, 0.6
    d = _synthetic_distances(n, rng, alpha)
    eps = 10.0 ** np.arange(-6.0, -1.99, 0.5)
    nf = nested_f(_nested(d, eps), eps, n, n_boot=200, rng=0)
    assert nf.changed[-1] == (d < 1e-2).sum() and nf.n[-1] == n
    assert np.allclose(nf.f, eps**alpha, rtol=0.25)
    ok = nf.changed[:-1] >= 30
    assert ok.sum() >= 5
    z = (nf.slope[ok] - alpha) / nf.slope_stderr[ok]
    assert np.all(np.abs(z) < 4), z
    a, se = secant_alpha(nf, 10**-5.2, 10**-2.3)
    assert abs(a - alpha) < 3 * se and se < 0.05
    # the secant of a power law is its exponent wherever it is taken; log_f_at interpolates between scales
    assert log_f_at(eps, nf.changed, eps[3]) == pytest.approx(math.log(nf.changed[3]))
    with pytest.raises(ValueError):
        secant_alpha(nf, 1e-9, 1e-3)  # below the measured scales


def test_nested_f_finds_a_step_of_the_exponent_and_refuses_bad_input():
    rng = np.random.default_rng(4)
    n = 400_000
    d = _synthetic_distances(n, rng, 0.5, eps_k=10**-3.5, alpha_fine=1.0)
    eps = 10.0 ** np.arange(-5.0, -1.99, 0.5)
    nf = nested_f(_nested(d, eps), eps, n, n_boot=200, rng=0)
    coarse, fine = nf.eps_mid > 10**-3.5, nf.eps_mid < 10**-3.5
    assert np.all(np.abs(nf.slope[coarse] - 0.5) < 4 * nf.slope_stderr[coarse])
    ok = fine & (nf.changed[:-1] >= 30)
    assert ok.any() and np.all(np.abs(nf.slope[ok] - 1.0) < 4 * nf.slope_stderr[ok])
    with pytest.raises(ValueError, match="ascending"):
        nested_f(_nested(d, eps)[:, ::-1], eps[::-1], n)
    with pytest.raises(ValueError, match="top"):
        nested_f(np.zeros((3, len(eps)), bool), eps, n)


def test_the_depth_below_a_scale_is_one_over_alpha_for_a_power_law_and_follows_a_step():
    eps = 10.0 ** np.arange(-8.0, -1.99, 0.5)
    assert np.allclose(log_depth(eps, 1e6 * eps**0.6), 1 / 0.6)
    # exponent 1 below 1e-5, 0.5 above: deep below the step the depth is 1, far above it tends to 2
    f = np.where(eps < 1e-5, 1e-5**0.5 * (eps / 1e-5), eps**0.5)
    d = log_depth(eps, 1e9 * f)
    assert np.allclose(d[eps <= 1e-5], 1.0) and 1.0 < d[-3] < d[-1] < 2.0
    assert np.isnan(log_depth(eps, 1e6 * eps**-0.1)).all()  # no finite depth where f does not fall
    with pytest.raises(ValueError):
        log_depth(eps, np.zeros_like(eps))


def test_the_settle_clock_reads_lambda_and_t0():
    """The mean settle time of the throws within ε of a border is T0 + (1/α − ln ε)/λ: with the depth correction the
    clock reads T0 itself, without it T0 + 1/(αλ); its free slope is λ either way."""
    rng = np.random.default_rng(5)
    n, alpha, lam, t0 = 400_000, 0.7, 24.0, 0.5
    d = _synthetic_distances(n, rng, alpha)
    t = t0 - np.log(d) / lam + rng.normal(0, 0.01, n)
    eps = 10.0 ** np.arange(-6.0, -1.99, 0.5)
    means, sems, counts = [], [], []
    for e in eps:
        tk = t[d < e]
        means.append(tk.mean())
        sems.append(tk.std(ddof=1) / math.sqrt(len(tk)))
        counts.append(len(tk))
    c = settle_clock(eps, means, sems, lam, log_depth(eps, counts))
    assert abs(c.lam_fit - lam) < 4 * c.lam_fit_stderr and c.lam_fit_stderr < 1.0
    assert c.t0 == pytest.approx(t0, abs=4 * c.t0_stderr + 1e-3)
    assert c.t0_fit == pytest.approx(t0, abs=0.02)  # the free line's intercept
    raw = settle_clock(eps, means, sems, lam)
    assert raw.t0 == pytest.approx(t0 + 1 / (alpha * lam), abs=4 * raw.t0_stderr + 1e-3)
    assert eps_of_t(t0 + 1.0, t0, lam) == pytest.approx(math.exp(-lam))


def _law_sample(n, rng, lam, alpha, eps_k, alpha_fine, t0=0.5):
    d = _synthetic_distances(n, rng, alpha, eps_k=eps_k, alpha_fine=alpha_fine)
    return d, t0 - np.log(d) / lam


@pytest.mark.slow  # about a second a case
@pytest.mark.parametrize("scale, verdict", [(1.0, "supported"), (1.25, "refuted")])
def test_the_law_on_a_synthetic_die_is_supported_and_a_wrong_rate_refuted(scale, verdict):
    """Lifetimes t = T0 − ln d/λ with f's exponent stepping from 0.6 to 1 at 1e-4: the hazard rises to λ, and the law
    predicts it window by window; the same lifetimes read with a clock 25 % too fast are refuted."""
    rng = np.random.default_rng(6)
    lam, n = 20.0, 300_000
    d, t = _law_sample(n, rng, lam, 0.6, 1e-4, 1.0)
    eps = 10.0 ** np.arange(-7.0, -0.99, 0.5)
    nf = nested_f(_nested(d, eps), eps, n, n_boot=200, rng=1)
    counted = nf.changed >= 10
    tk = [t[d < e].mean() for e in eps]
    sk = [t[d < e].std(ddof=1) / math.sqrt((d < e).sum()) for e in eps]
    c = settle_clock(eps[counted], np.array(tk)[counted], np.array(sk)[counted], lam,
                     log_depth(eps[counted], nf.changed[counted]))
    life = 0.5 + (t - 0.5) / scale
    hz, _ = quantile_hazard(life, QUANTILES)
    ws = [law_window(float(h), float(se), float(a), float(b), nf, c.t0, lam, counted=counted)
          for h, se, a, b in zip(hz.h, hz.stderr, hz.t0, hz.t1)]
    tested = [w for w in ws if w["pred"] is not None]
    assert len(tested) >= 6
    v = law_verdict([w["z"] for w in tested])
    assert v["verdict"] == verdict, [(w["h"], w["pred"], w["z"]) for w in tested]
    if scale == 1.0:
        lev = levels_off(hz.h, hz.stderr, lam)
        assert lev["from_window"] is not None and hz.t0[lev["from_window"]] > c.t0 + math.log(1e4) / lam - 0.1
        assert abs(lev["z"][0]) > 3  # the early hazard, at α = 0.6, lies far below λ


def test_law_verdicts_and_where_the_hazard_levels_off():
    assert law_verdict([0.5, -1.2, 1.9])["verdict"] == "supported"
    assert law_verdict([0.5, -3.4, 1.0])["verdict"] == "refuted"
    assert law_verdict([0.5, 2.5, 1.0])["verdict"] == "undetermined"
    assert law_verdict([0.5, None, float("nan")])["verdict"] == "undetermined"  # one window is too few
    assert law_verdict([1.0, 1.0, 1.0])["chi2"] == pytest.approx(3.0)
    lev = levels_off([10.0, 15.0, 23.0, 24.0], [0.5, 0.5, 1.0, 1.0], 24.0)
    assert lev["from_window"] == 2 and lev["z"][0] == pytest.approx(-28.0)
    hp = (23.0**2 + 24.0**2) / (23.0 + 24.0)  # events (h/σ)² over their exposures events/h
    assert lev["pooled_z"][2] == pytest.approx((hp - 24.0) / (hp / math.sqrt(23.0**2 + 24.0**2)))
    assert levels_off([10.0, 24.0, 10.0], [0.5, 1.0, 0.5], 24.0)["from_window"] is None
    # one window 2.5σ low among windows at λ: pooled, the hazard has levelled off; 3.5σ low, it has not
    assert levels_off([24.0, 21.5, 24.0], [1.0, 1.0, 1.0], 24.0)["from_window"] == 0
    assert levels_off([24.0, 20.5, 24.0], [1.0, 1.0, 1.0], 24.0)["from_window"] == 2


def test_rays_are_unit_and_neighbours_lie_eps_times_the_norm_away():
    ics = np.random.default_rng(7).normal(size=(50, 6)) * 10
    r = unit_rays(50, 6, 0)
    assert np.allclose(np.linalg.norm(r, axis=1), 1.0)
    for e in (1e-3, 1e-9):
        moved = along_rays(ics, r, e)
        assert np.allclose(np.linalg.norm(moved - ics, axis=1), e * np.linalg.norm(ics, axis=1), rtol=1e-6)
        assert np.allclose((moved - ics) / np.linalg.norm(moved - ics, axis=1, keepdims=True), r, atol=1e-6)
