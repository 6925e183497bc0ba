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
