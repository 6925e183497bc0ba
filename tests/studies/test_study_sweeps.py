"""Study q (sweeps): registered, its numerics, and its quick run end to end (its part of the shared
``dicetrace analyze all --quick``).

The quick run (three conditions, two windows, 25² maps, 60 pairs per scale; about 10 s on two cores) checks the
pipeline and that every number the report quotes is written with its model, integrator, tolerance, certificate
and error bar.  The full run is ``dicetrace analyze sweeps --out analysis``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.studies import LETTERS, TITLES, resolve
from dicetrace.studies import study_sweeps as sw
from dicetrace.studies.study_doubly_transient import FLOOR_SHARE, MIN_CHANGED
from dicetrace.studies.study_sweeps_render import series


def test_registered_as_study_q():
    assert LETTERS["q"] == "sweeps" and resolve(["q"]) == resolve(["sweeps"]) == ["sweeps"] and "sweeps" in TITLES


def test_numerics_fit_each_measurement():
    for cond, over in sw.CONDITIONS.items():
        pairs = sw._config(cond, tol=sw.TOL, tol_growth=0.0)  # f(ε), settle and commit times: uniform and tight
        assert pairs.numerics.tol == 1e-10 and pairs.numerics.tol_growth == 0.0
        m = sw.map_options(cond)  # outcome maps: the graded schedule
        assert m["integrator"] == "contact-tsit5" and m["tol_growth"] > 0
        ref = sw._config(cond, **sw.REFERENCE).numerics  # the certificate's reference: another integrator
        chk = sw._config(cond, **sw.REFERENCE_CHECK).numerics
        assert len({ref.integrator, chk.integrator, m["integrator"]}) == 3
        for k, v in over.items():
            assert getattr(pairs.preset, k) == v
    # one parameter moved at a time, three values of each
    gammas = {sw._config(c).preset.gamma for c in sw.CONDITIONS if sw._config(c).preset.k == 5e5}
    ks = {sw._config(c).preset.k for c in sw.CONDITIONS if sw._config(c).preset.gamma == 0.005}
    assert len(gammas) == 3 and len(ks) == 3 and len(sw.WINDOWS) >= 3
    assert set(sw.QUICK_CONDITIONS) <= set(sw.CONDITIONS) and set(sw.QUICK_WINDOWS) <= set(sw.WINDOWS)


def _row(cond, window, gamma, k, faces, se, converged=True):
    return {"condition": cond, "window": window, "gamma": gamma, "k": k,
            "map": {"converged": converged, "puy": {"verdict": "smooth"}, "wada": {"wada": False},
                    "faces": {"faces": {str(i + 1): {"fraction": f, "stderr": se} for i, f in enumerate(faces)}}}}


def test_face_changes_use_the_block_errors_and_the_series_hold_one_parameter():
    even = [1 / 6] * 6
    moved = [0.30, 0.10, 0.15, 0.15, 0.15, 0.15]
    rows = [_row("physical", "home", 0.005, 5e5, even, 0.01), _row("γ 0.01", "home", 0.01, 5e5, moved, 0.01),
            _row("k 2e5", "home", 0.005, 2e5, even, 0.01, converged=False)]
    ch = {c["condition"]: c for c in sw.face_changes(rows)}
    assert ch["γ 0.01"]["face"] == 1 and ch["γ 0.01"]["changed"] and ch["γ 0.01"]["both_converged"]
    assert ch["γ 0.01"]["z"] == pytest.approx((0.30 - 1 / 6) / math.hypot(0.01, 0.01))
    assert not ch["k 2e5"]["changed"] and not ch["k 2e5"]["both_converged"]
    # wider block errors make the same change unresolved
    wide = [_row("physical", "home", 0.005, 5e5, even, 0.05), _row("γ 0.01", "home", 0.01, 5e5, moved, 0.05)]
    assert not sw.face_changes(wide)[0]["changed"]
    assert [r["condition"] for r in series(rows, "gamma")["home"]] == ["physical", "γ 0.01"]
    assert [r["condition"] for r in series(rows, "k")["home"]] == ["k 2e5", "physical"]


@pytest.fixture(scope="module")
def quick(copy_of_study):
    """Study q's part of the shared ``dicetrace analyze all --quick`` run, copied (its rerender writes into it)."""
    return copy_of_study("sweeps")


@pytest.mark.slow
def test_quick_run_writes_every_measure(quick):
    out, r = quick
    assert r["study"] == "sweeps" and r["quick"] is True
    n = len(sw.QUICK_CONDITIONS) * len(sw.QUICK_WINDOWS)
    assert [(x["condition"], x["window"]) for x in r["rows"]] == [(c, w) for c in sw.QUICK_CONDITIONS
                                                                   for w in sw.QUICK_WINDOWS]
    for name in ("q_eps_alpha", "q_hazard", "q_faces"):
        assert (out / r["figures"][name]["path"]).stat().st_size > 0
    for key in ("maps", "faces", "pairs"):
        assert r["tables"][key].count("\n") == n + 1
    for x in r["rows"]:
        m, p = x["map"], x["pairs"]
        # the map names its numerics and its certificate, and the certificate decides the status
        assert m["numerics"]["integrator"] == sw.MAP_INTEGRATOR and m["numerics"]["tol_growth"] == sw.MAP_GROWTH
        assert m["reference"]["integrator"] == sw.REFERENCE["integrator"]
        c = m["certificate"]
        assert 0 <= c["ci"][0] <= c["fraction"] <= c["ci"][1] <= 1 and c["n"] == 40
        assert m["converged"] == (c["fraction"] >= sw.CERTIFIED)
        assert m["status"] == ("converged" if m["converged"] else "statistics only")
        # faces: every node counted once; neighbouring nodes share faces, so the block error is never far below
        # the binomial error of independent nodes (a 25² map of these windows is nearly speckle: about equal)
        faces = m["faces"]["faces"]
        assert sum(f["fraction"] for f in faces.values()) + m["faces"]["no_face"] == pytest.approx(1.0)
        for f in faces.values():
            assert f["stderr"] == max(f["stderr_small_block"], f["stderr_large_block"])
            if 0 < f["fraction"] < 1:
                assert f["stderr"] > 0.6 * math.sqrt(f["fraction"] * (1 - f["fraction"]) / 625)
        assert m["puy"]["verdict"] in ("fractal", "smooth", "undetermined")
        assert m["wada"]["error"] is not None or m["wada"]["wada"] in (True, False)
        # f(ε) at a uniform tight tolerance, counted only above its floor
        assert p["numerics"]["tol"] == sw.TOL and p["numerics"]["tol_growth"] == 0.0 and p["n_pairs"] == 60
        f = np.array(p["f"], dtype=float)
        assert np.all((f >= 0) & (f <= 1)) and f[-1] > f[0]
        for counted, fv, k in zip(p["counted"], f, p["changed"]):
            if counted:
                assert p["floor_bound"] <= FLOOR_SHARE * fv and k >= MIN_CHANGED
        assert p["hazard"] is None or p["hazard"]["commit"]["median_s"] <= p["hazard"]["settle"]["median_s"]
    assert len(r["summary"]["face_changes"]) == n - len(sw.QUICK_WINDOWS)
    # the finer maps: the same ball in window units (more nodes) and the same ball in nodes, each certified
    assert [(f["condition"], f["window"]) for f in r["finer"]] == list(sw.FINER_QUICK)
    assert r["tables"]["finer"].count("\n") == len(sw.FINER_QUICK) + 1
    for f in r["finer"]:
        assert f["res"] == sw.FINER_RES_QUICK and f["base_res"] == 25
        assert f["puy_same_scale"]["eps_nodes"] == round(sw.PUY_EPS_QUICK * (f["res"] - 1) / 24)
        assert f["puy_same_nodes"]["eps_nodes"] == sw.PUY_EPS_QUICK
        assert f["wada_same_scale"]["r_max"] == round(5 * (f["res"] - 1) / 24)
        assert f["converged"] == (f["certificate"]["fraction"] >= sw.CERTIFIED) and f["certificate"]["n"] == 40


@pytest.mark.slow
def test_rerender_from_the_results_changes_no_number(quick):
    out, r = quick
    again = sw.rerender(out)
    assert again["tables"] == r["tables"] and again["rows"] == r["rows"] and again["summary"] == r["summary"]
    assert set(again["figures"]) == set(r["figures"])
