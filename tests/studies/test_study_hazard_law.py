"""Study r (hazard_law): registered, its numerics and scales, and its quick run end to end (its part of the shared
``dicetrace analyze all --quick``: 1500 throws per model, about 20 s on two cores).

The quick run checks the pipeline and that every field the report reads is written, with its model, integrator,
tolerance, error bars and verdicts.  The full run is ``dicetrace analyze hazard-law --out analysis``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dicetrace.analysis.border_rates import edge_saddle
from dicetrace.studies import LETTERS, TITLES, resolve
from dicetrace.studies import study_hazard_law as hl


def test_registered_as_study_r_with_a_hyphenated_name():
    assert LETTERS["r"] == "hazard_law" and "hazard_law" in TITLES
    assert resolve(["r"]) == resolve(["hazard-law"]) == ["hazard_law"]


def test_every_model_is_a_uniform_tight_tolerance_and_the_scales_reach_1e_12():
    for model in hl.MODELS:
        cfg, tight = hl._config(model, hl.TOL), hl._config(model, hl.TOL_TIGHT)
        assert cfg.numerics.integrator == "contact-tsit5" and cfg.numerics.tol == hl.TOL == 1e-10
        assert cfg.numerics.tol_growth == 0.0 and tight.numerics.tol == pytest.approx(hl.TOL / 10, rel=1e-12)
        eps = hl.scales(hl.MODELS[model][2], quick=False)
        assert eps[-1] == pytest.approx(hl.MODELS[model][2]) and eps[0] == pytest.approx(1e-12)
        assert np.allclose(np.diff(np.log10(eps)), 0.5)  # half decades
        # below 1e-9 every half decade down to 1e-12
        assert {round(v, 6) for v in np.log10(eps[eps < 1.01e-9])} == {-9.0, -9.5, -10.0, -10.5, -11.0, -11.5, -12.0}
    assert hl.MODELS["physical"][3] == pytest.approx(hl.TOL / 10) and hl.MODELS["seed"][3] == hl.TOL
    assert hl._config("seed", hl.TOL).preset.name == "seed" and hl._config("physical", hl.TOL).preset.name == "physical"
    assert hl.N_FULL == 100_000 and hl.QUANTILES[-2:] == (0.999, 0.9997)


@pytest.fixture(scope="module")
def quick(copy_of_study):
    """Study r's part of the shared quick run, copied (its rerender writes into the copy)."""
    return copy_of_study("hazard_law")


@pytest.mark.long
def test_quick_run_writes_every_field_the_report_reads(quick):
    out, r = quick
    assert r["study"] == "hazard_law" and r["quick"] is True and r["tol"] == hl.TOL
    assert [row["model"] for row in r["rows"]] == list(hl.MODELS)
    assert (out / r["figures"]["r_hazard_law"]["path"]).stat().st_size > 0
    assert r["tables"]["summary"].count("\n") == len(hl.MODELS) + 1
    for row in r["rows"]:
        assert row["integrator"] == "contact-tsit5" and row["tol"] == hl.TOL and row["tol_growth"] == 0.0
        assert row["tight_tol"] == hl.TOL_TIGHT and row["n"] == hl.N_QUICK
        assert row["nested_tol"] == hl.MODELS[row["model"]][3] <= hl.TOL
        assert row["edge_saddle"] == pytest.approx(edge_saddle(config=hl._config(row["model"], hl.TOL)).rate)
        f = row["f"]
        s = len(f["eps"])
        assert len(f["changed"]) == len(f["counted"]) == len(f["floor_bound"]) == len(f["t_mean"]) == s
        assert len(f["slope"]) == s - 1 and f["eps"][-1] == pytest.approx(row["top"])
        assert f["changed"][-1] == f["top_changed"] and f["n_bases"] <= row["n"]
        # nested pairs: a finer scale changes no more often than f's top (the leak aside, measured apart)
        assert all(c <= f["top_changed"] for c in f["changed"])
        for c, fv, b, k in zip(f["counted"], f["f"], f["floor_bound"], f["changed"]):
            if c:
                assert b <= hl.FLOOR_SHARE * fv and k >= hl.MIN_CHANGED
        leak = f["leak"]
        assert 0 <= leak["changed"] <= leak["pairs"] and leak["scale"] == pytest.approx(f["eps"][-2])
        # windows: closed, between the quantiles, Poisson errors, each with a verdict
        ws = row["windows"]
        assert len(ws) == len(hl.QUANTILES) - 1
        assert [w["q0"] for w in ws] == list(hl.QUANTILES[:-1])
        for w in ws:
            assert w["t0"] < w["t1"] and w["verdict"] in ("consistent", "inconsistent", "undetermined")
            if w["events"] > 0:
                assert w["h_err"] == pytest.approx(w["h"] / math.sqrt(w["events"]))
            if w["pred"] is not None:
                assert w["pred"] == pytest.approx(w["alpha"] * row["edge_saddle"])
                assert w["eps_lo"] < w["eps_hi"] and math.isfinite(w["z"])
        assert row["verdict"]["verdict"] in ("supported", "refuted", "undetermined")
        assert row["verdict"]["n_windows"] == sum(1 for w in ws if w["tail"] and w["z"] is not None)
        cert = row["certificate"]
        assert cert["tol"] == hl.TOL_TIGHT and cert["thrown"] == cert["late"] + cert["random"]
        assert len(cert["h_tight"]) == len(ws) and 0 <= cert["outcome_flips"] <= cert["thrown"]


@pytest.mark.long
def test_rerender_from_the_results_changes_no_number(quick):
    out, r = quick
    again = hl.rerender(out)
    assert again["tables"] == r["tables"] and again["rows"] == r["rows"]
    assert set(again["figures"]) == set(r["figures"])


REPO = Path(__file__).resolve().parents[2]


@pytest.mark.skipif(not (REPO / "analysis" / "results" / "hazard_law.json").exists(), reason="no committed results")
def test_the_report_states_the_laws_verdict_as_measured_and_no_longer_calls_it_unmeasured():
    """Section n said the hazard law was "not measured"; section r measures it: the committed report gives each model's
    verdict from the committed results, in section r, in section n's pointer and in the answers table."""
    report = (REPO / "analysis" / "REPORT.md").read_text()
    r = json.loads((REPO / "analysis" / "results" / "hazard_law.json").read_text())
    sec_n = report[report.index("## n. "):report.index("## o. ")]
    sec_r = report[report.index("## r. "):report.index("## Method notes")]
    assert "not measured** here" not in sec_n and "section r" in sec_n
    answers = report[report.index("## Answers"):report.index("## a. ")]
    for model in ("seed", "physical"):
        verdict = r["by"][model]["verdict"]["verdict"]
        assert verdict in ("supported", "refuted", "undetermined")
        assert f"*`{model}`: the law is {verdict}.*" in sec_r
        assert f"**{verdict}** for `{model}`" in sec_n
        assert f"**{verdict}**" in answers
    w = r["by"]["physical"]["windows"][2]
    assert f"hazard is {w['h']:.1f} ± {w['h_err']:.1f} /s" in " ".join(sec_r.split())
