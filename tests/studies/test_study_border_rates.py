"""Study o (border_rates): the quick run's outputs (the shared ``dicetrace analyze all --quick`` of CI), its numerics,
the near-border rates against each preset's edge saddle, and its re-analysis from the raw profiles."""

from __future__ import annotations

import json
import shutil

import pytest

from dicetrace.studies import LETTERS, resolve


def test_registered_with_a_letter_and_a_hyphenated_name():
    letter = {v: k for k, v in LETTERS.items()}["border_rates"]
    assert resolve([letter]) == ["border_rates"] and resolve(["border-rates"]) == ["border_rates"]


@pytest.mark.slow
def test_quick_run_uses_uniform_tight_numerics_and_finds_the_edge_saddles(quick_run):
    _, results = quick_run
    r = results["border_rates"]
    assert r["quick"] is True
    for key in ("seed", "physical"):
        m = r[key]
        num = m["numerics"]
        # a uniform tolerance (no loosening over the throw), checked at a tenth of it
        assert num["integrator"] == "contact-tsit5" and num["tol"] == 1e-13 and num["tol_growth"] == 0.0
        assert num["check_tol"] == pytest.approx(1e-14)
        assert m["bisect_max_width"] < num["bisect_width"] == 1e-11
        assert 0 <= m["ends"]["n_changed"] <= m["ends"]["n_ends"] == 2 * m["n_borders"]
        near, whole = m["near"], m["all_range"]
        assert near["d_lo"] < near["d_hi"] < whole["d_hi"] == pytest.approx(1e-3)
        # the rate near the border is the preset's edge saddle to 3 % even on the quick run's few borders; the fit
        # over the whole distance range is biased upward by the approach to the saddle
        assert near["median"] == pytest.approx(m["analytic"]["edge"], rel=0.03)
        assert whole["median"] > near["median"] + 3 * near["total"]
    assert r["physical"]["analytic"]["edge"] > r["seed"]["analytic"]["edge"]  # the slipping pivot is faster
    for key in ("seed", "physical"):  # the limit as the range shrinks: one decade from d_lo, a range systematic
        lim = r[key]["limit"]
        assert lim["d_lo"] == r[key]["near"]["d_lo"] and lim["d_hi"] == pytest.approx(10 * lim["d_lo"])
        assert lim["value"] == pytest.approx(r[key]["analytic"]["edge"], rel=0.05) and lim["syst"] >= 0
    # the friction sweep's quick setting (v_reg 40): its own slipping-pivot root, far from the held pivot's
    (name, f), = r["friction"].items()
    assert name == "v_reg 40" and f["edge"] > r["seed"]["analytic"]["edge"] + 5
    assert f["value"] == pytest.approx(f["edge"], rel=0.03)


@pytest.mark.slow
@pytest.mark.long
def test_reanalysis_from_the_raw_profiles_gives_the_same_numbers(quick_run, tmp_path):
    from dicetrace.studies.study_border_rates import rerender

    out, results = quick_run
    mine = tmp_path / "out"
    (mine / "results").mkdir(parents=True)
    shutil.copy(out / "results" / "border_rates.json", mine / "results")
    (mine / "results" / "raw").mkdir()
    shutil.copy(out / "results" / "raw" / "border_rates_profiles.csv", mine / "results" / "raw")
    rerender(mine)
    again = json.loads((mine / "results" / "border_rates.json").read_text())
    for key in ("seed", "physical"):
        for part in ("near", "all_range", "stability", "ends", "flat"):
            assert again[key][part] == results["border_rates"][key][part]
    assert set(again["figures"]) == {"local_slope", "range", "lambdas", "friction"}
    assert again["seed"]["limit"] == results["border_rates"]["seed"]["limit"]
    assert again["friction"] == results["border_rates"]["friction"]
    assert all((mine / f["path"]).stat().st_size > 0 for f in again["figures"].values())


@pytest.mark.slow  # seconds (a subprocess or a long fit): the quick loop skips it, CI runs it
def test_the_limit_as_the_range_shrinks_finds_the_rate_at_the_border_and_the_bias_of_longer_ranges():
    # Synthetic borders: T(d) = T0 − ln(d)/λ + ln(1 + d/d_c)/λ, quantised to 1 ms: the local rate is λ near the border
    # and rises toward d_c. The shortest range (one decade from d_lo) gives λ; the longer ranges lie above it
    # (a one-sided range systematic), as the fits over the whole range do for the die.
    import numpy as np

    from dicetrace.analysis.border_rates import bisect_many, profiles
    from dicetrace.studies import study_border_rates as sbr

    lam, d_c = 24.4, 1e-6

    def classify(pts):
        return np.where(np.atleast_2d(pts)[:, 0] < 0.0123456789, 2, 5)

    def settle(pts):
        pts = np.atleast_2d(pts)
        d = np.abs(pts[:, 0] - 0.0123456789)
        t = 1.0 - np.log(d) / lam + np.log1p(d / d_c) / lam
        return classify(pts), np.round(t / 1e-3) * 1e-3

    rng = np.random.default_rng(1)
    pairs = [(np.array([0.0123456789 - u, y]), np.array([0.0123456789 + v, y])) for u, v, y in rng.uniform(1e-4, 2e-3, (12, 3))]
    br = bisect_many(classify, pairs, tol=1e-12)
    prof = profiles(settle, br, sbr.DISTS)
    lim = sbr._range_limit(br, prof, prof, 1e-10, 1e-8, len(br.p_lo), np.random.default_rng(2))
    assert lim["d_lo"] == pytest.approx(1e-10) and lim["d_hi"] == pytest.approx(1e-9)
    assert lim["value"] == pytest.approx(lam, rel=0.01)
    assert lim["syst_hi"] > lim["syst_lo"] and lim["tol_shift"] == 0.0  # longer ranges are biased upward
    v = np.array([x for x in lim["values"] if x is not None])
    assert v[-1] > lam * 1.2  # the whole range, to 1e-3 ≫ d_c: the approach's bias
    assert lim["text"].startswith(f"{lim['value']:.2f} ± ")
