"""Study m (corner): registered, its quick run's results (part of the shared ``dicetrace analyze all --quick``,
tests/studies/conftest.py) and the verdict it writes on the writeup's section 4.3 from its results alone.

The full run is ``dicetrace analyze corner --out analysis``.
"""

from __future__ import annotations

import copy

from dicetrace.studies import LETTERS, TITLES, resolve
from dicetrace.studies.study_corner_render import faces_up, verdict


def test_registered_as_study_m():
    assert LETTERS["m"] == "corner" and resolve(["m"]) == ["corner"] and "corner" in TITLES


def test_quick_run_results(quick_run):
    out, results = quick_run
    R = results["corner"]
    assert R["quick"] is True
    for key in ("m_corner_face_map", "m_triple_points"):
        assert (out / R["figures"][key]["path"]).is_file()
    ph = R["rates"]["physical"]
    assert abs(ph["relative"]) < 1e-6 and ph["error"] > 0  # the simulator's rate is the slipping pivot's
    assert abs(R["rates"]["seed_converged"]["relative"]) < 1e-2
    rings = R["face_maps"]["models"]["physical"]["rings"]
    assert all(r["faces"] == [4, 5, 6] and r["n_borders"] == 3 and r["on"] == ["edge"] for r in rings)
    assert all(m["converged"] in (True, False) and m["res"] >= 3 for m in R["triple"]["maps"])
    assert R["verdict"] == verdict(R)
    assert "Refuted" in R["verdict"] or "Undetermined" in R["verdict"]


def _results(vertex: bool, three_rings: bool = True, near: bool = True) -> dict:
    ring = {"tilt": 1e-6, "spin_ratio": 0.0, "faces": [4, 5, 6] if three_rings else [4, 5], "n_borders": 3,
            "max_offset": 1e-9}
    point = {"status": "vertex" if vertex else "split", "three_on_every_circle": vertex, "labels": [1, 3, 5],
             "throw": {"d_min": 1e-3 if near else 0.9, "node": 6}}
    return {"rates": {"physical": {"rate": 23.1267, "error": 1e-7, "analytic": 23.1267, "sigmas": 0.1,
                                   "max_drift": 1e-9}},
            "face_maps": {"models": {"physical": {"rings": [ring]}}},
            "triple": {"points": [point], "tol": 1e-11, "radii": [1e-3, 1e-7],
                       "maps": [{"random": [{"d_min": 0.7}], "border": [{"d_min": 0.5}], "n_candidates": 3}]}}


def test_faces_up_are_opposite_the_pivot_faces():
    assert faces_up(1) == [4, 5, 6]  # node 1 lies on faces 1, 2, 3
    assert faces_up(6) == [1, 3, 5]  # node 6 (x+, y-, z+) lies on faces 6, 2, 4
    assert faces_up(8) == [1, 2, 3]


def test_verdict_follows_the_evidence():
    assert "at 1 of the 1 points the three faces" in verdict(_results(True))
    assert "**Refuted:**" in verdict(_results(True)) and "is their mechanism" in verdict(_results(True))
    assert "not shown to be their mechanism" in verdict(_results(True, near=False))
    r = _results(True)
    r["triple"]["points"][0]["throw"]["d_min"] = 0.2  # nearer than the controls, outside the linear range
    assert "still turning" in verdict(r)
    v = verdict(_results(False))
    assert "Refuted in principle" in v and "undetermined" in v
    assert "**Undetermined.**" in verdict(_results(False, three_rings=False))
    r = _results(True)
    r2 = copy.deepcopy(r)
    r2["triple"]["points"][0]["three_on_every_circle"] = False  # a point without three sectors on every circle
    assert "**Refuted:**" not in verdict(r2)


def test_verdict_quotes_the_rate_budget_and_the_reproducibility_across_integrators():
    r = _results(True)
    r["rates"]["physical"].update(rate=23.126695561, analytic=23.126695596, stat=4e-14, numerics_syst=2e-10,
                                  range_syst_hi=1.4e-8, range_syst_lo=1.2e-7, relative=-1.5e-9,
                                  range_syst_relative=5e-9, sigmas=-2.4)
    r["triple"]["independent"] = {"contact-dop853": "seed, contact-dop853 tol 1e-10 uniform",
                                  "contact-tsit5": "seed, contact-tsit5 tol 1e-10 uniform"}
    r["triple"]["reproducibility"] = {"n_points": 3, "n_found_by_all": 3, "spread_min": 7e-9, "spread_max": 4e-8,
                                      "radius_coarsest": 1e-7, "radius_finest": 1e-8, "box_max": 4.2e-11,
                                      "n_with_common_radius": 2, "n_without_common_radius": 1, "largest_radius": 1e-7}
    v = verdict(r)
    # the budget: no regression error, the fit range's systematic, an offset undetermined at 2.4 σ
    assert "fit range +1.4e-08 / −1.2e-07 /s" in v and "undetermined at that level" in v and "-2.4 σ" in v
    assert "1.5e-09 of itself below the slipping pivot's" in v
    # the location: reproducible to the integrators' common scale, not to one integrator's box
    assert "3 of the 3 points are found by every integrator" in v and "7.0e-09 … 4.0e-08 of the window" in v
    assert "about 2 of them every integrator sees the three faces on circles down to 1e-07 of the window" in v
    assert "about 1 not even on the largest circle" in v and "not to the hunt's box of 4e-11" in v
    # what is refuted: the 2-D statement, not the 6-D one
    assert "the writeup's conclusion that a 2-D map has no triple points" in v
    assert "vertices of the 6-D space itself" in v and "untouched" in v
    assert "IC⁶ joining 7 cells. " not in v
