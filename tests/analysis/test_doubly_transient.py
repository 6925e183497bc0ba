"""The measures of doubly transient chaos (dicetrace.analysis.doubly_transient) on synthetic data with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.analysis import doubly_transient as dt


def _crossover_f(eps, a, eps_c, beta):
    return a * eps / (1 + (eps / eps_c) ** (1 - beta))


def _pairs(f_true, n, rng):
    """Changed flags (n, scales) with P(changed at scale s) = f_true[s]; nested (a pair changed at s stays changed
    at every larger scale), as neighbours farther apart differ more often."""
    u = rng.uniform(size=(n, 1))
    return u < np.asarray(f_true)[None]


def _local_slope(eps, a, eps_c, beta):
    x = (eps / eps_c) ** (1 - beta)
    return 1 - (1 - beta) * x / (1 + x)


@pytest.mark.slow  # about a second
def test_local_slopes_of_a_power_law_with_a_crossover():
    rng = np.random.default_rng(1)
    eps = 10.0 ** np.arange(-9, -5.9, 0.5)
    f_true = _crossover_f(eps, 1e6, 1e-8, 0.4)
    ls = dt.local_slopes(_pairs(f_true, 100_000, rng), eps, n_boot=100, rng=2)
    np.testing.assert_allclose(ls.f, f_true, rtol=0.25)
    exact = np.diff(np.log(f_true)) / np.diff(np.log(eps))  # the secant slopes the estimator measures
    ok = np.isfinite(ls.slope_stderr)
    assert ok.sum() == 6
    z = (ls.slope[ok] - exact[ok]) / ls.slope_stderr[ok]
    assert np.all(np.abs(z) < 4), z
    # the bootstrap error is the binomial one: var(ln f_{i+1} - ln f_i) for nested pairs ~ 1/k_i - 1/k_{i+1}
    k = ls.changed
    se = np.sqrt(np.abs(1 / k[:-1] - 1 / k[1:])) / np.diff(np.log(eps))
    np.testing.assert_allclose(ls.slope_stderr[ok], se[ok], rtol=0.35)
    # slope 1 at the fine end, near beta at the coarse end
    assert exact[0] > 0.8 and ls.slope[0] > 0.65 and abs(ls.slope[-1] - 0.45) < 0.1
    assert np.allclose(ls.eps_mid, np.sqrt(eps[:-1] * eps[1:]))


def test_local_slopes_leave_out_scales_without_changes_and_invalid_pairs():
    c = np.zeros((100, 3), dtype=bool)
    c[:10, 1:] = True
    c[:40, 2] = True
    ls = dt.local_slopes(c, [1e-3, 1e-2, 1e-1], n_boot=50)
    assert np.isnan(ls.slope[0]) and np.isnan(ls.slope_stderr[0])
    assert ls.slope[1] == pytest.approx(math.log(4) / math.log(10))
    valid = np.ones_like(c)
    valid[:5, 2] = False  # five of the changed pairs at the last scale do not count
    assert dt.local_slopes(c, [1e-3, 1e-2, 1e-1], valid=valid, n_boot=20).f[2] == pytest.approx(35 / 95)
    with pytest.raises(ValueError, match="increasing"):
        dt.local_slopes(c, [1e-2, 1e-3, 1e-1])


@pytest.mark.slow  # a second or more (a fit, a subprocess): the quick loop skips it, CI runs it
def test_crossover_fit_recovers_eps_c_and_beta():
    rng = np.random.default_rng(3)
    eps = 10.0 ** np.arange(-9.5, -5.9, 0.5)
    f_true = _crossover_f(eps, 1e6, 1e-8, 0.4)
    c = _pairs(f_true, 100_000, rng)
    cx = dt.crossover_fit(c, eps, used=np.ones(len(eps), bool), n_boot=60, rng=4)
    assert cx.status == "fitted"
    assert abs(math.log10(cx.eps_c) - (-8)) < max(4 * cx.log10_eps_c_stderr, 0.05)
    assert abs(cx.beta - 0.4) < max(4 * cx.beta_stderr, 0.02)
    assert 0 < cx.log10_eps_c_stderr < 0.5 and 0 < cx.beta_stderr < 0.15


@pytest.mark.slow  # a second or more (a fit, a subprocess): the quick loop skips it, CI runs it
def test_crossover_fit_status_outside_the_scales():
    rng = np.random.default_rng(5)
    eps = 10.0 ** np.arange(-8, -4.9, 0.5)
    smooth = dt.crossover_fit(_pairs(1e3 * eps, 100_000, rng), eps, used=np.ones(len(eps), bool), n_boot=20)
    assert smooth.status == "above"  # slope 1 throughout: the crossover lies above the scales
    fractal = dt.crossover_fit(_pairs(0.5 * (eps / 1e-5) ** 0.5, 100_000, rng), eps, used=np.ones(len(eps), bool),
                               n_boot=20)
    assert fractal.status == "below" and abs(fractal.beta - 0.5) < 0.05
    few = dt.crossover_fit(_pairs(1e3 * eps, 1000, rng), eps, used=np.arange(len(eps)) < 3)
    assert few.status == "too few scales" and math.isnan(few.eps_c)


def test_hazard_of_exponential_lifetimes_is_constant():
    rng = np.random.default_rng(6)
    t = rng.exponential(1 / 4.0, 50_000)
    hz = dt.hazard_curve(t, np.linspace(0, 1.0, 11))
    assert np.all(np.abs(hz.h - 4.0) < 4 * hz.stderr)
    w = dt.hazard_windows(t)
    assert len(w.h) == 4 and np.all(np.abs(w.h - 4.0) < 4 * w.stderr)
    assert dt.compare(w.h[-1], w.stderr[-1], w.h[0], w.stderr[0])["verdict"] != "inconsistent"


def test_hazard_of_censored_exponential_lifetimes_is_unbiased():
    rng = np.random.default_rng(7)
    t = rng.exponential(1 / 2.0, 40_000)
    cap = 0.6
    cen = t >= cap
    hz = dt.hazard_curve(np.minimum(t, cap), [0.0, 0.3, 0.6 + 1e-12], censored=cen)
    assert np.all(np.abs(hz.h - 2.0) < 4 * hz.stderr)
    assert hz.events.sum() == (~cen).sum()


def test_hazard_of_weibull_lifetimes_rises_as_2t():
    rng = np.random.default_rng(8)
    t = rng.weibull(2.0, 80_000)  # P(T > t) = exp(-t^2): h(t) = 2 t
    edges = np.linspace(0, 2.0, 9)
    hz = dt.hazard_curve(t, edges)
    # the bin's maximum-likelihood rate is the cumulative hazard over the exposure-weighted bin: (b^2 - a^2) / (b - a)
    # for survivors spread as exp(-t^2); a*b close: ~ a + b
    expect = np.array([(math.exp(-a * a) - math.exp(-b * b)) / (math.sqrt(math.pi) / 2 * (math.erf(b) - math.erf(a)))
                       for a, b in zip(edges[:-1], edges[1:])])
    assert np.all(np.abs(hz.h - expect) < 4 * hz.stderr)
    w = dt.hazard_windows(t)
    assert dt.compare(w.h[-1], w.stderr[-1], w.h[0], w.stderr[0])["z"] > 3  # rising: no steady escape rate


def test_discrete_hazard_of_geometric_counts():
    rng = np.random.default_rng(9)
    n = rng.geometric(0.3, 20_000) - 1  # P(N = n) = 0.3 · 0.7^n
    h = dt.discrete_hazard(n)
    assert np.all(np.abs(h["h"] - 0.3) < 4 * h["stderr"])
    assert h["at_risk"][0] == 20_000 and np.all(h["at_risk"] >= 20)
    with pytest.raises(ValueError):
        dt.discrete_hazard([-1, 2])


def test_covariate_hazard_with_time_as_covariate_is_the_hazard_curve():
    rng = np.random.default_rng(10)
    t = rng.weibull(2.0, 3000)
    grid = np.linspace(0, 4, 4001)
    edges = np.linspace(0, 2.0, 5)
    ch = dt.covariate_hazard([grid] * len(t), [grid] * len(t), t, edges)
    hz = dt.hazard_curve(t, edges)
    np.testing.assert_allclose(ch.exposure, hz.exposure, rtol=2e-3)
    assert np.array_equal(ch.events, hz.events)
    # censored throws add time, never an event
    ch2 = dt.covariate_hazard([grid] * len(t), [grid] * len(t), t, edges, events=np.zeros(len(t), bool))
    assert ch2.events.sum() == 0 and np.allclose(ch2.exposure, ch.exposure)


def test_commit_steps_from_contact_sets():
    m3, m6 = dt.FACE_NODE_MASK[4], dt.FACE_NODE_MASK[1]  # outcome 3 rests on face 4; outcome 6 on face 1
    node = {k: 1 << (k - 1) for k in range(1, 9)}
    seqs = [
        # lands on node 1 (off face 4), leaves it (commits: in the air, one landing so far), lands on 2 (face 4),
        # then 2+4, 2+4+6+8
        ([0, node[1], 0, node[2], node[2] | node[4], m3], [0, 10, 20, 30, 40, 50], 3, 60),
        # never touches another face: commits at its first contact
        ([0, node[1], node[1] | node[2]], [0, 5, 9], 6, 12),
        # its last set is off its face: commits when it ends
        ([0, node[8]], [0, 7], 6, 15),
        # no outcome
        ([0, node[1]], [0, 3], -1, 9),
    ]
    sets = np.concatenate([s for s, *_ in seqs])
    steps = np.concatenate([st for _, st, *_ in seqs])
    off = np.concatenate([[0], np.cumsum([len(s) for s, *_ in seqs])])
    commit, landings = dt.commit_steps(sets, steps, off, [o for *_, o, _ in seqs], [e for *_, e in seqs])
    assert commit.tolist() == [20, 5, 15, -1]
    assert landings.tolist() == [1, 1, 1, -1]
    assert m6 == 0b1111


def test_perturbed_moves_each_ic_by_eps_times_its_norm():
    ics = np.array([[1.0, 2, 3, 4, 5, 6], [10.0, 0, 0, 0, 0, 0]])
    moved = dt.perturbed(ics, 1e-3, 0)
    np.testing.assert_allclose(np.linalg.norm(moved - ics, axis=1), 1e-3 * np.linalg.norm(ics, axis=1))


def test_floor_test_counts_changed_verdicts():
    a = np.zeros((200, 2), dtype=bool)
    b = a.copy()
    b[:4, 1] = True
    fl = dt.floor_test(a, b)
    assert fl["flips"].tolist() == [0, 4] and fl["fraction"][1] == pytest.approx(0.02)
    assert fl["hi"][0] == pytest.approx(3.84 / 203.84, rel=1e-3)  # Wilson bound of 0 of 200
    assert fl["lo"][1] < 0.02 < fl["hi"][1]


def test_compare_verdicts():
    assert dt.compare(1.0, 0.1, 1.1, 0.1)["verdict"] == "consistent"
    assert dt.compare(1.0, 0.1, 2.0, 0.1)["verdict"] == "inconsistent"
    assert dt.compare(1.0, 0.1, 1.35, 0.1)["verdict"] == "undetermined"
    assert dt.compare(1.0, math.nan, 1.0, 0.1)["verdict"] == "undetermined"


@pytest.mark.slow  # a second or more (a fit, a subprocess): the quick loop skips it, CI runs it
def test_crossover_fit_with_saturation_uses_the_saturated_scales():
    rng = np.random.default_rng(11)
    eps = 10.0 ** np.arange(-10.5, -2.9, 0.5)
    g = _crossover_f(eps, 1e7, 1e-9, 0.4)
    f_sat = 0.8
    f_true = f_sat * g / (1 + g)
    assert f_true[-1] > 0.5 * f_sat  # the coarse scales are saturated
    c = _pairs(f_true, 100_000, rng)
    cx = dt.crossover_fit(c, eps, used=np.ones(len(eps), bool), f_sat=f_sat, n_boot=40, rng=12)
    assert cx.status == "fitted"
    assert abs(math.log10(cx.eps_c) + 9) < max(4 * cx.log10_eps_c_stderr, 0.05)
    assert abs(cx.beta - 0.4) < max(4 * cx.beta_stderr, 0.02)
    # the model without saturation reads the saturated scales as a lower beta
    naive = dt.crossover_fit(c, eps, used=np.ones(len(eps), bool), n_boot=5, rng=12)
    assert naive.beta < cx.beta - 0.1


def test_throw_floor_bounds_the_pair_floor():
    a = np.array([1, 2, 3, 4, 5, 6] * 50)
    b = a.copy()
    b[:3] = 6
    tf = dt.throw_floor(a, b)
    assert tf["flips"] == 3 and tf["n"] == 300 and tf["fraction"] == pytest.approx(3 / 300)
    assert tf["lo"] < 3 / 300 < tf["hi"]


def test_pair_verdicts_compare_each_perturbed_face_with_the_unperturbed_one():
    # row 0: the unperturbed faces of 3 throws; rows 1-2: two scales (0: unsettled, -1: blown up)
    out = np.array([[1, 2, 0], [1, 3, 0], [4, 2, 5]])
    changed, valid = dt.pair_verdicts(out)
    assert changed.tolist() == [[False, True], [True, False], [False, True]]
    assert valid.tolist() == [[True, True], [True, True], [False, False]]


def test_a_hazards_record_is_its_curve():
    t = np.array([0.1, 0.2, 0.2, 0.5, 0.9, 1.0])
    h = dt.hazard_curve(t, np.array([0.0, 0.3, 1.1]))
    d = h.as_dict()
    assert d["events"] == h.events.tolist() == [3, 3] and d["h"] == h.h.tolist() and d["t0"] == [0.0, 0.3]


def test_hazard_shape_tells_a_rise_from_a_dip_and_from_noise():
    # the windows of section n as measured: `physical` rises step by step; `seed` falls 17.1 → 14.4 (z ≈ −5.4) before
    # it rises past its first window
    phys = dt.hazard_shape([7.5, 10.1, 11.9, 14.9], [0.1, 0.3, 0.5, 0.9])
    assert phys["shape"] == "rises" and phys["min_step_z"] > 0 and len(phys["steps"]) == 3
    seed = dt.hazard_shape([17.1, 14.4, 21.6, 27.3], [0.3, 0.4, 0.8, 1.6])
    assert seed["shape"] == "dips, then rises" and seed["min_step_z"] == pytest.approx(-2.7 / 0.5)
    assert seed["lowest_window"] == 1
    # a fall of 2.5σ that never recovers beyond 3σ: not monotone, no rise claimed
    wob = dt.hazard_shape([10.0, 7.5, 9.0], [0.5, 0.9, 0.9])
    assert wob["shape"] == "not monotone"
    # up, a fall of 4.6σ, up again, all above the first window: not a dip below the start, not monotone either
    assert dt.hazard_shape([5.0, 51.1, 30.3, 37.5], [0.3, 3.7, 3.6, 6.9])["shape"] == "not monotone"
    # constant within the errors: flat; exponential lifetimes give a flat hazard
    rng = np.random.default_rng(9)
    w = dt.hazard_windows(rng.exponential(1 / 4.0, 50_000))
    assert dt.hazard_shape(w.h, w.stderr)["shape"] == "flat"
    # Weibull(2) lifetimes: h = 2t rises through every window
    w = dt.hazard_windows(rng.weibull(2.0, 80_000))
    assert dt.hazard_shape(w.h, w.stderr)["shape"] == "rises"
    assert dt.hazard_shape([5.0], [0.1])["shape"] == "undetermined"
    # section q's preset in home: 8.8 → 17.8 through every window, but 2.7σ from first to last: a weak rise
    assert dt.hazard_shape([8.8, 13.3, 15.9, 17.8], [0.6, 1.1, 1.9, 3.3])["shape"] == "rises weakly"


def test_tail_scan_of_exponential_lifetimes_has_no_systematic_beyond_noise_and_finds_a_rising_tail():
    rng = np.random.default_rng(10)
    t = rng.exponential(1 / 4.0, 100_000)
    s = dt.tail_scan(t)
    assert s["starts"] == [0.99, 0.97, 0.95, 0.9] and s["reference"] == 1
    assert abs(s["value"] - 4.0) < 3 * s["stat"]  # memoryless: every tail has the rate 4
    assert s["syst"] < 3 * s["stat"]
    assert s["from_s"][1] == pytest.approx(-math.log(0.03) / 4.0, rel=0.03)  # the 97 % quantile of Exp(4)
    # Weibull(2): h = 2t, so a later tail has a larger hazard: the 99 % tail lies above the 97 % one (syst_hi), the
    # 90 % one below (syst_lo)
    w = rng.weibull(2.0, 100_000)
    s = dt.tail_scan(w)
    assert s["syst_hi"] > 3 * s["stat"] and s["syst_lo"] > 3 * s["stat"]
    # the maximum-likelihood hazard past t_q: the events, a share exp(−t_q²), over the time at risk, ∫ S = (√π/2)·erfc(t_q)
    tq = math.sqrt(-math.log(0.03))
    assert abs(s["value"] - 0.03 / (math.sqrt(math.pi) / 2 * math.erfc(tq))) < 3 * s["stat"]
    # too few events in the shortest tail: that tail has no value, the others still do
    s = dt.tail_scan(rng.exponential(1.0, 1000), min_events=20)
    assert s["values"][0] is None and s["value"] is not None


def test_tail_scan_without_enough_events_past_the_reference_has_no_value():
    rng = np.random.default_rng(11)
    s = dt.tail_scan(rng.exponential(1.0, 300), min_events=20)  # 9 events past the 97 % quantile
    assert s["value"] is None and s["syst"] is None
    assert s["values"][0] is None and s["values"][1] is None and s["values"][3] is not None  # 30 past the 90 %


def test_tail_scan_from_windows_is_the_tail_scan_of_the_lifetimes():
    # Weibull(2) lifetimes: the hazard past a quantile from the windows alone equals the one from the lifetimes
    rng = np.random.default_rng(12)
    t = rng.weibull(2.0, 60_000)
    w = dt.hazard_windows(t).as_dict()
    s = dt.tail_scan_windows(w)
    assert s["starts"] == [0.97, 0.9, 0.75, 0.5]
    assert s["value"] == pytest.approx(w["h"][-1]) and s["stat"] == pytest.approx(w["stderr"][-1])
    past90 = dt.hazard_curve(t, [np.quantile(t, 0.9), np.nextafter(t.max(), np.inf)])
    assert s["values"][1] == pytest.approx(past90.h[0], rel=1e-9)
    assert s["syst_lo"] > 3 * s["stat"] and s["syst_hi"] == 0.0  # a rising hazard: earlier tails lie below
    assert dt.tail_scan_windows({"h": [1.0, 2.0], "events": [10, 10]})["value"] is None  # a window was dropped
