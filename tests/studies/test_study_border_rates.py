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


@pytest.mark.slow
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
    assert set(again["figures"]) == {"local_slope", "lambdas"}
    assert all((mine / f["path"]).stat().st_size > 0 for f in again["figures"].values())
