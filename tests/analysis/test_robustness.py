"""The robustness of a measurement (analysis.robustness): fits over nested ranges with known answers, locations
re-found by several integrators, and the text of the two errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.analysis.robustness import (common_scale, group_spread, one_sided_z, range_scan, relocate,
                                           stat_syst, syst_note)


def _linear_in_width(v0: float, a: float, e: float):
    """A fit whose value is exactly v0 + a·W over a range W decades wide, with standard error e."""

    def fit(lo, hi):
        return v0 + a * math.log10(hi / lo), e

    return fit


def test_a_trend_with_the_range_is_a_one_sided_systematic_and_the_extrapolation_finds_the_limit():
    # Known answer: v(W) = 22.80 + 0.04 W over W = 1, 1.5, ..., 5 decades. The shortest range gives 22.84; the
    # longer ones lie above it only (syst_hi = 0.04·4 = 0.16), the line through them meets W = 0 at 22.80 exactly,
    # 0.04 below (syst_lo).
    d_lo = 1e-10
    ranges = [(d_lo, d_lo * 10**w) for w in np.arange(1.0, 5.01, 0.5)]
    s = range_scan(_linear_in_width(22.80, 0.04, 0.01), ranges, extrapolate=True)
    assert s.value == pytest.approx(22.84) and s.stat == 0.01
    assert s.syst_hi == pytest.approx(0.16) and s.syst_lo == pytest.approx(0.04)
    assert s.extrapolated == pytest.approx(22.80, abs=1e-9) and s.trend == pytest.approx(0.04)
    # the line's error at W = 0 from the fits' errors (taken as independent): 0.01·√(Σw²/(nΣw² − (Σw)²))
    w = np.arange(1.0, 5.01, 0.5)
    assert s.extrapolated_stderr == pytest.approx(0.01 * math.sqrt((w**2).sum() / (len(w) * (w**2).sum() - w.sum()**2)))
    assert s.syst == pytest.approx(0.16) and s.syst_dominates
    assert np.allclose(s.widths, np.arange(1.0, 5.01, 0.5))
    # only the first three ranges in the systematic: 0.04·1 above
    s3 = range_scan(_linear_in_width(22.80, 0.04, 0.01), ranges, syst_over=3)
    assert s3.syst_hi == pytest.approx(0.04) and s3.syst_lo == 0.0 and s3.n_syst == 3
    assert math.isnan(s3.extrapolated) and len(s3.values) == len(ranges)  # every range is still fitted
    d = s.as_dict()
    assert d["value"] == pytest.approx(22.84) and d["syst_dominates"] is True and len(d["ranges"]) == 9


def test_a_least_squares_slope_of_a_curved_law_extrapolates_to_the_local_slope_at_the_inner_end():
    # Known answer: T(x) = s0·x + s1·x²/2 with x = −ln(d/d_lo) ≥ 0 (a local slope that grows linearly with x). A
    # least-squares line over the evenly spaced points of [0, X] has the slope of the curve at X/2, so the fits
    # are s0 + s1·X/2, linear in the width: extrapolated to width 0 they give s0, the slope at d_lo.
    s0, s1 = 1 / 22.8, 2e-4
    x = np.linspace(0.0, 5 * math.log(10), 21)
    t = s0 * x + s1 * x**2 / 2

    def fit(lo, hi):
        sel = (x >= lo - 1e-12) & (x <= hi + 1e-12)
        return float(np.polyfit(x[sel], t[sel], 1)[0])

    ranges = [(0.0, k * math.log(10) / 4) for k in range(4, 21, 2)]
    s = range_scan(fit, ranges, widths=[b for _, b in ranges], extrapolate=True)
    assert s.value == pytest.approx(s0 + s1 * ranges[0][1] / 2, rel=1e-9)
    assert s.extrapolated == pytest.approx(s0, rel=1e-9)
    assert s.syst_lo == pytest.approx(s1 * ranges[0][1] / 2, rel=1e-6)
    assert math.isnan(s.stat) and s.syst_dominates  # no statistical error: the systematic is all there is


def test_flat_values_have_no_systematic_and_noise_within_its_error_does_not_dominate():
    ranges = [(1.0, 10.0**w) for w in (1, 2, 3, 4)]
    s = range_scan(lambda lo, hi: (24.43, 0.05), ranges, extrapolate=True)
    assert s.syst_lo == pytest.approx(0, abs=1e-12) and s.syst_hi == pytest.approx(0, abs=1e-12)
    assert not s.syst_dominates
    rng = np.random.default_rng(3)
    vals = iter(24.43 + rng.normal(0, 0.001, 4))
    s = range_scan(lambda lo, hi: (next(vals), 0.05), ranges, extrapolate=True)
    assert s.syst < 0.01 and not s.syst_dominates
    # noise far above the fits' errors: the extrapolation departs from the value by less than its own error and
    # stays out of the systematic, which is the spread of the values alone
    vals = [24.43, 24.60, 24.30, 24.50]
    it = iter(vals)
    s = range_scan(lambda lo, hi: (next(it), 0.2), ranges, extrapolate=True)
    assert abs(s.extrapolated - 24.43) < s.extrapolated_stderr
    assert s.syst_hi == pytest.approx(0.17) and s.syst_lo == pytest.approx(0.13)


def test_failed_fits_are_kept_as_nan_and_left_out_of_the_systematic():
    ranges = [(1.0, 10.0), (1.0, 100.0), (1.0, 1000.0)]

    def fit(lo, hi):
        if hi == 100.0:
            raise ValueError("too few points")
        return 5.0 if hi == 10.0 else 5.3

    s = range_scan(fit, ranges)
    assert math.isnan(s.values[1]) and s.n_syst == 2 and s.syst_hi == pytest.approx(0.3)
    with pytest.raises(ValueError, match="reference"):
        range_scan(lambda lo, hi: math.nan, ranges)
    with pytest.raises(ValueError, match="nested"):
        range_scan(fit, [(1.0, 100.0), (1.0, 10.0)])
    with pytest.raises(ValueError, match="nested"):
        range_scan(fit, [(1.0, 10.0), (2.0, 100.0)])


def test_a_reference_other_than_the_shortest():
    ranges = [(0.97, 1.0), (0.95, 1.0), (0.90, 1.0)]
    vals = {0.97: (27.3, 1.6), 0.95: (25.0, 1.0), 0.90: (23.6, 0.9)}
    s = range_scan(lambda lo, hi: vals[lo], ranges, reference=1)
    assert s.value == 25.0 and s.stat == 1.0 and s.syst_hi == pytest.approx(2.3) and s.syst_lo == pytest.approx(1.4)
    assert s.syst_dominates


def test_relocate_measures_the_spread_between_integrators_against_the_box():
    # Known answer: the reference's point, one 3e-10 away and one 4e-10 away (a 3-4-5 offset): spread 4e-10, above
    # the reference's box of 1.4e-11, so the location is reproducible to 4e-10 only.
    ref = (0.011213377030, 0.062484302151)
    pts = {"contact-adaptive": ref, "contact-dop853": (ref[0] + 3e-10, ref[1]),
           "contact-tsit5": (ref[0], ref[1] - 4e-10)}
    r = relocate(pts, reference="contact-adaptive", box=1.4e-11)
    assert r.spread == pytest.approx(4e-10, rel=1e-5) and r.reproducible == r.spread
    assert r.distances[1] == pytest.approx(3e-10, rel=1e-5) and r.found.all()
    # an integrator that finds no point: the location is not reproducible at all
    r2 = relocate({**pts, "contact-substep": None}, reference="contact-adaptive", box=1.4e-11)
    assert r2.spread == math.inf and not r2.found[-1]
    d = r2.as_dict()
    assert d["spread"] is None and d["points"][-1] is None and d["found"] == [True, True, True, False]
    # all at one point: reproducible to the box
    r3 = relocate({"a": ref, "b": ref}, reference="a", box=1e-11)
    assert r3.spread == 0.0 and r3.reproducible == 1e-11
    with pytest.raises(ValueError, match="reference"):
        relocate({"a": None, "b": ref}, reference="a", box=1e-11)


def test_common_scale_is_where_every_integrator_still_sees_the_references_faces():
    # the case: three faces for everyone down to 1e-8 of the window, at 1e-9 one integrator sees two faces,
    # at 1e-10 all see one: reproducible to 1e-8, although the reference sees three down to 1e-9
    scales = [1e-7, 1e-8, 1e-9, 1e-10]
    seen = {"contact-adaptive": [(1, 3, 5), (1, 3, 5), (1, 3, 5), (3,)],
            "contact-tsit5": [(1, 3, 5), (1, 3, 5), (1, 3, 5), (3,)],
            "contact-dop853": [(1, 3, 5), (1, 3, 5), (1, 3), (3,)]}
    assert common_scale(scales, seen, reference="contact-adaptive") == 1e-8
    assert common_scale(scales, {k: v for k, v in seen.items() if k != "contact-dop853"},
                        reference="contact-adaptive") == 1e-10  # they agree on one face too
    # requiring three faces: all three agree on one face at 1e-10, which is not the point's three
    three = {k: [len(v) == 3 for v in obs] for k, obs in seen.items() if k != "contact-dop853"}
    assert common_scale(scales, three, reference="contact-adaptive", require=True) == 1e-9
    seen["contact-dop853"][0] = (1, 3)
    assert common_scale(scales, seen, reference="contact-adaptive") is None
    with pytest.raises(ValueError, match="descending"):
        common_scale(scales[::-1], seen, reference="contact-adaptive")


def test_the_text_of_two_errors_and_the_one_sided_comparison():
    assert stat_syst(22.843, 0.009, 0.043, 0.104) == "22.84 ± 0.01 (stat) +0.10 −0.04 (range)"
    assert stat_syst(24.5, 0.08, 0.1, 0.1, what="fit range") == "24.50 ± 0.08 (stat) ± 0.10 (fit range)"
    assert stat_syst(1.0, math.nan, 0.0, 0.2, spec=".1f") == "1.0 ± – (stat) +0.2 −0.0 (range)"
    assert syst_note(0.05, 0.04) == ""
    note = syst_note(0.009, 0.104)
    assert "exceeds its statistical error (0.01)" in note and "(0.10)" in note
    # the target below the value: only the lower side counts
    assert one_sided_z(22.843, 0.009, 0.04, 0.10, 22.797) == pytest.approx(0.046 / math.hypot(0.009, 0.04))
    assert one_sided_z(22.843, 0.009, 0.04, 0.10, 23.0) == pytest.approx(-0.157 / math.hypot(0.009, 0.10))
    assert math.isnan(one_sided_z(1.0, 0.0, 0.0, 0.0, 1.0))


def test_group_spread_is_the_scatter_between_groups():
    # three windows joining 2/9, 15/28 and 18/24 of their cells: mean 0.5026, sample sd 0.2654, over √3: 0.1532
    g = group_spread([2 / 9, 15 / 28, 18 / 24])
    assert g["n"] == 3 and g["mean"] == pytest.approx((2 / 9 + 15 / 28 + 18 / 24) / 3)
    assert g["std"] == pytest.approx(np.std([2 / 9, 15 / 28, 18 / 24], ddof=1))
    assert g["spread"] == pytest.approx(g["std"] / math.sqrt(3)) and g["min"] == pytest.approx(2 / 9)
    one = group_spread([0.4, math.nan])
    assert one["n"] == 1 and one["mean"] == 0.4 and math.isnan(one["spread"])
    assert group_spread([])["n"] == 0
