"""Study n (doubly_transient): registered, and its quick run end to end (its part of the shared ``dicetrace analyze all --quick``).

The quick run (about 15 s on two cores: 300 pairs per scale, four scales, three models) checks the pipeline and
that every number the report quotes is written with its model, integrator, tolerance and error bar.  The full run
is ``dicetrace analyze doubly-transient --out analysis``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.analysis.border_rates import edge_saddle
from dicetrace.studies import LETTERS, resolve
from dicetrace.studies import study_doubly_transient as dts


def test_registered_as_study_n_with_a_hyphenated_name():
    assert LETTERS["n"] == "doubly_transient"
    assert resolve(["n"]) == resolve(["doubly-transient"]) == ["doubly_transient"]


def test_every_condition_is_a_uniform_tight_tolerance():
    for cond in dts.CONDITIONS:
        cfg = dts._config(cond, dts.TOL)
        assert cfg.numerics.integrator == "contact-tsit5"
        assert cfg.numerics.tol == dts.TOL and cfg.numerics.tol_growth == 0.0
        assert dts._config(cond, dts.TOL_FLOOR).numerics.tol == pytest.approx(dts.TOL / 10, rel=1e-12)
    assert dts._config("physical k 5e6", dts.TOL).preset.k == 5e6
    assert dts._config("physical γ 0.01", dts.TOL).preset.gamma == 0.01
    assert dts._config("physical", dts.TOL).preset.gamma == dts._config("physical γ 0.0025", dts.TOL).preset.gamma * 2
    assert set(dts.QUICK_CONDITIONS) <= set(dts.CONDITIONS)


@pytest.fixture(scope="module")
def quick(copy_of_study):
    """Study n's part of the shared ``dicetrace analyze all --quick`` run, copied (its rerender writes into the copy)."""
    return copy_of_study("doubly_transient")


@pytest.mark.slow
def test_quick_run_writes_every_measure(quick):
    out, r = quick
    assert r["study"] == "doubly_transient" and r["quick"] is True
    assert [row["condition"] for row in r["rows"]] == list(dts.QUICK_CONDITIONS)
    for name in ("n_slopes", "n_hazard", "n_tests"):
        assert (out / r["figures"][name]["path"]).stat().st_size > 0
    for key in ("slopes", "hazard", "tests"):
        assert r["tables"][key].count("\n") == len(dts.QUICK_CONDITIONS) + 1
    for row in r["rows"]:
        # each row names its model and numerics
        assert row["integrator"] == "contact-tsit5" and row["tol"] == dts.TOL and row["tol_growth"] == 0.0
        assert row["floor_tol"] == dts.TOL_FLOOR and row["preset"] in ("physical", "seed")
        s = len(row["eps"])
        assert len(row["f"]) == len(row["floor_hi"]) == len(row["counted"]) == s and len(row["slope"]) == s - 1
        f = np.array(row["f"], dtype=float)
        assert np.all((f >= 0) & (f <= 1)) and f[-1] > f[0]  # farther neighbours differ more often
        assert row["pairs"][0] <= row["n_pairs"] == 300
        # a counted scale is above its floor and has enough changes
        assert row["floor_throws"] == 100 * (s + 1) and row["floor_bound"] >= 2 * row["floor_throw_fraction"]
        for c, fv, k in zip(row["counted"], f, row["changed"]):
            if c:
                assert row["floor_bound"] <= dts.FLOOR_SHARE * fv and k >= dts.MIN_CHANGED
        hz = row["hazard"]["commit"]
        assert hz["kappa_mid"] > 0 and hz["kappa_mid_stderr"] > 0
        assert hz["median_s"] <= row["hazard"]["settle"]["median_s"]  # a throw commits before it stops
        assert row["hazard"]["bounce"]["h"][0] >= 0
        lam = row["lambda"]["survivors"]
        assert lam["n"] >= 3 and 0 < lam["mean"] < 100 and lam["stderr"] > 0
        assert row["edge_rate"]["rate"] == pytest.approx(row["edge_rate_analytic"], rel=0.15)
        # the edge tests use the preset's analytic edge saddle (held pivot for seed, slipping for physical) and the
        # settle clock; the commit clock's test is gone
        assert row["edge_saddle"] == pytest.approx(edge_saddle(config=dts._config(row["condition"], dts.TOL)).rate)
        assert "edge_late_hazard" not in row["tests"] and "edge_settle" in row["tests"]
        assert row["tests"]["edge_settle"]["y"] == pytest.approx(row["alpha_fine"] * row["edge_saddle"], nan_ok=True)
        assert row["hazard_shape"]["commit"]["shape"] in ("rises", "rises weakly", "dips, then rises", "not monotone",
                                                          "flat", "undetermined")
        assert row["tail"]["settle"]["starts"] == [0.99, 0.97, 0.95, 0.9]
        assert row["eps_c_resolved"] in (True, False)
        for t in row["tests"].values():
            assert t["verdict"] in ("consistent", "inconsistent", "undetermined")
            if t["verdict"] != "undetermined":
                assert math.isfinite(t["z"]) and t["x_err"] > 0


@pytest.mark.slow
def test_rerender_from_the_results_changes_no_number(quick):
    out, r = quick
    again = dts.rerender(out)
    assert again["tables"] == r["tables"] and again["rows"] == r["rows"]
    assert set(again["figures"]) == set(r["figures"])


def test_compare_with_syst_adds_the_systematic_of_the_targets_side():
    # κ_late 14.1 ± 0.8 with a tail systematic +1.0 / −3.0 against 20.5 ± 3.0: the target lies above, so the upper
    # side counts: z = −6.4 / √(0.8² + 1.0² + 3.0²) = −1.98, consistent; from the statistics alone z = −2.06
    c = dts.compare_with_syst(14.1, 0.8, 3.0, 1.0, 20.5, 3.0)
    assert c["z"] == pytest.approx(-6.4 / math.sqrt(0.64 + 1.0 + 9.0)) and c["verdict"] == "consistent"
    assert c["z_stat"] == pytest.approx(-6.4 / math.hypot(0.8, 3.0)) and c["syst_dominates"] is True
    assert dts.compare_with_syst(30.0, 0.8, 3.0, 1.0, 20.0, 0.5)["z"] == pytest.approx(10.0 / math.sqrt(0.64 + 9 + 0.25))
    assert dts.compare_with_syst(None, None, None, None, 20.0, 0.5)["verdict"] == "undetermined"


@pytest.mark.slow
def test_the_seed_release_is_set_by_its_start_not_by_its_tilt(monkeypatch):
    # released 1e-7 and 1e-5 rad off its edge, the seed die has nearly the same tilt 0.1 s later (the release's first
    # steps, not the tilt, set the motion), so the fit from ten times the start tilt measures that transient and
    # moves by more than 1 /s; fitted from 0.1 s on, both give the held pivot's rate to 0.5 %
    monkeypatch.setattr(dts, "RELEASE_DTS", (1e-4,))
    monkeypatch.setattr(dts, "RELEASE_TILTS", (1e-7, 1e-5))
    d = dts.release_diagnosis(dts._config("seed", dts.TOL))
    a, b = d["rows"]
    assert 0.5 < a["tilt_at_0_1_s"] / b["tilt_at_0_1_s"] < 2.0
    assert abs(a["rate"] - b["rate"]) > 1.0
    held = edge_saddle(preset="seed").rate
    for r in (a, b):
        assert r["late"][0]["rate"] == pytest.approx(held, rel=0.005)
    assert d["rate_min"] < held < d["rate_max"]
