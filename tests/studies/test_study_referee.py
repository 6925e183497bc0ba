"""Study k (referee), CI-sized: its part of the shared ``dicetrace analyze all --quick`` run (tests/studies/conftest.py),
and its numbers (those of ``dicetrace analyze referee --quick`` alone: each study seeds its own generator, and a grid
it finds in the run's cache is the grid it would have simulated).

The full run (``dicetrace analyze referee --out analysis``) regenerates the committed results; this quick run
checks that every part runs and that the answers the controls know come out.
"""

from __future__ import annotations

import math

import pytest


@pytest.fixture
def referee(quick_run):
    out, results = quick_run
    return out, results["referee"]


@pytest.mark.slow
def test_vertex_controls(referee):
    _, R = referee
    sector, strip = R["vertices"]["controls"]
    assert sector["dim_meet3"] == 0.0 and all(n == 1 for n in sector["meet3"])  # one triple point, every scale
    assert strip["dim_meet3"] is None and all(n == 0 for n in strip["meet3"])  # no vertex
    assert max(strip["any3"]) > 0  # ... although boxes hold three outcomes (the old count's artefact)
    for r in R["vertices"]["rows"]:
        assert r["dim_meet3"] is None or r["dim_meet3"] >= 0  # never negative


@pytest.mark.slow
def test_floor_reaches_1e_2_with_intervals(referee):
    _, R = referee
    for w, d in R["floor"].items():
        assert max(d["deltas"]) == pytest.approx(1e-2)
        for f in d["floor"]:
            assert f["ci"][0] <= f["fraction"] <= f["ci"][1]
            assert -1 <= f["kappa"] <= 1
        assert d["floor"][0]["fraction"] == 1.0  # δ = 1e-12 changes nothing in 40 throws


@pytest.mark.slow
def test_edge_saddle_and_pooled_fits(referee):
    _, R = referee
    L = R["lambda"]
    assert L["analytic_fixed_pivot"] == pytest.approx(math.sqrt(3 * 980 / (2 * math.sqrt(2) * 2)), rel=1e-12)
    conv = [r for r in L["releases"] if r["model"] == "seed, contact-substep dt 0.25 ms" and r["tilt0"] == 1e-4][0]
    assert conv["rate"] == pytest.approx(L["analytic_fixed_pivot"], rel=0.01)  # see tests/analysis/test_edge.py
    for m in ("discrete", "converged"):
        assert L["fits"][m]["n"] == len(L["fits"][m]["all"]) > 0
        assert L["fits"][m]["total"] >= L["fits"][m]["syst"]


@pytest.mark.slow
def test_other_parts_ran(referee):
    out, R = referee
    assert R["onecell"]["verdict"] in ("converged", "undetermined")
    assert len(R["onecell"]["series"]) >= 3
    assert {r["min_steps"] for r in R["entropy"]["rows"]} == {1, 3, 5}
    assert [r["k"] for r in R["stiffness"]["rows"]] == [5e5, 5e7]
    assert all(r["pen_median_cm"] > 0 for r in R["stiffness"]["rows"])
    # a stiffer ground sinks less: peak penetration falls with k
    assert R["stiffness"]["rows"][1]["pen_median_cm"] < R["stiffness"]["rows"][0]["pen_median_cm"]
    for name in ("k_vertices", "k_floor", "k_alpha", "k_lambda", "k_onecell", "k_entropy", "k_stiffness"):
        assert (out / "figures" / f"{name}.png").stat().st_size > 0


def test_alpha_verdict_text_follows_the_data():
    """The k3 verdict quotes α with its error, or the number of scales when a two-scale fit has
    none, and says what f(ε) does at the smallest scales: flat at zero (no point changes), or
    a few points that still change (a numerical floor)."""
    from dicetrace.studies.study_referee import _alpha_text, _zero_up_to, alpha_small_scale_note

    eps = [1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3]
    clean = {"n": 2000, "eps_rel": eps, "f": [0, 0, 0, 0, 0.004, 0.04], "alpha": 0.71, "alpha_stderr": None,
             "used": [False, False, False, False, True, True]}
    noisy = dict(clean, f=[0.001, 0.001, 0.001, 0.0015, 0.005, 0.04], alpha=0.93, alpha_stderr=0.012)
    assert _alpha_text(clean) == {"alpha_text": "0.71 (2 scales, no error bar)", "n_scales": 2}
    assert _alpha_text(noisy)["alpha_text"] == "0.93 ± 0.01"
    assert _alpha_text({"alpha": None}) == {"alpha_text": "none (too few changes)", "n_scales": 0}
    assert _zero_up_to(clean) == 1e-5 and _zero_up_to(noisy) is None
    rows = {"home/converged": clean, "zoom-out/converged": dict(clean, f=[0, 0, 0.001, 0.002, 0.005, 0.04]),
            "home/discrete": noisy}
    assert alpha_small_scale_note(rows).startswith("No point in 2000 changes outcome at ε ≤ 1e-07 of the width")
    rows["zoom-out/converged"] = noisy
    assert alpha_small_scale_note(rows).startswith("At the smallest ε (1e-08 of the width) 2 point(s) in 2000")
    assert _alpha_text(dict(clean, alpha_stderr=float("nan")))["alpha_text"] == "0.71 (2 scales, no error bar)"
