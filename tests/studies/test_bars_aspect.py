"""Study aspect: the home window against the die's aspect ratio; the cube bit for bit, the exponent's fit, the
committed results, the quick run and the report section (built only where its results are)."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from dicetrace.analysis.face_fractions import face_fractions
from dicetrace.analysis.simulator import sample_window
from dicetrace.params import make_config
from dicetrace.studies import report
from dicetrace.studies import study_aspect as sa

REPO = Path(__file__).resolve().parents[2]
COMMITTED = REPO / "analysis" / "aspect"


@pytest.fixture(scope="module")
def committed():
    path = COMMITTED / "results.json"
    if not path.exists():
        pytest.skip("the committed aspect results are not in this checkout")
    return json.loads(path.read_text())


def test_the_aspect_one_prism_is_the_cube_bit_for_bit():
    """The prism of aspect 1 is the physical cube: the same map of the home window, outcomes and settle times alike
    to the last bit; the other aspects are other dice (their maps differ)."""
    cube = sample_window(sa.WINDOW, 9, config=make_config("physical"))
    one = sample_window(sa.WINDOW, 9, config=sa.config(1.0))
    assert np.array_equal(cube.labels, one.labels) and np.array_equal(cube.t_settle_s, one.t_settle_s)
    flat = sample_window(sa.WINDOW, 9, config=sa.config(0.8))
    assert not np.array_equal(cube.labels, flat.labels)
    assert sa.config(1.25).preset.body.face_heights_cm.tolist() == pytest.approx([1, 1, 1.25, 1.25, 1, 1])


def test_the_exponent_of_a_power_law_is_its_power_and_saturated_scales_stay_out():
    eps = np.logspace(-8, -3, 11)
    f = np.minimum(0.02 * (eps / 1e-6) ** 0.6, 0.8)  # a power law up to saturation at 0.8
    e = sa.exponent(eps, f, n=10**6, f_sat=0.8)
    assert e["alpha"] == pytest.approx(0.6, rel=1e-9) and e["range"]["syst"] == pytest.approx(0, abs=1e-9)
    assert max(e["scales"]) <= eps[f <= 0.4].max() and min(e["scales"]) == eps[f * 10**6 >= sa.MIN_CHANGES].min()
    few = sa.exponent(eps, f, n=100, f_sat=0.8)  # too few points: changes below MIN_CHANGES at most scales
    assert few["alpha"] is None and "unsaturated" in few["error"]


def test_the_committed_run_is_the_full_study(committed):
    assert committed["aspects"] == list(sa.ASPECTS) and committed["n_points"] == sa.N_POINTS
    assert committed["eps_rel"] == pytest.approx(sa.EPS_REL) and committed["map_res"] == sa.MAP_RES
    for k, m in committed["by"].items():
        n = m["n_points"]
        assert m["changed"] == [round(f * n) for f in m["f"]]
        assert all(lo <= f <= hi for f, lo, hi in zip(m["f"], m["f_low"], m["f_high"]))
        assert sum(m["points"]["faces"]) + m["points"]["edge"] + m["points"]["unsettled"] == n


def test_the_committed_summary_and_map_shares_follow_from_the_committed_data(committed):
    """Summary recomputed from the committed per-aspect numbers, and the maps' face shares from maps.npz."""
    data = {k: committed[k] for k in ("window", "ranges", "aspects", "n_points", "eps_rel", "map_res", "seed",
                                      "min_changes", "by", "control")}
    again = sa.summarise(data)
    for name in ("border_fraction", "square_faces"):
        for key in ("values", "chi2", "p_value", "same_for_every_aspect"):
            assert again[name][key] == pytest.approx(committed["summary"][name][key], rel=1e-12)
    assert again["alpha"]["values"] == committed["summary"]["alpha"]["values"]
    assert again["integrator_noise"]["aspects_fitted_below_noise"] == \
        committed["summary"]["integrator_noise"]["aspects_fitted_below_noise"]
    with np.load(COMMITTED / "maps.npz") as z:
        for k, m in committed["by"].items():
            grid = z[f"c_{k}"]
            assert grid.shape == (sa.MAP_RES, sa.MAP_RES)
            share = face_fractions(grid)["faces"]
            for f in range(1, 7):
                assert share[str(f)]["fraction"] == pytest.approx(m["map"]["faces"][str(f)]["fraction"], abs=1e-15)
    text = (COMMITTED / "aspect.md").read_text()
    assert f"runs from {committed['summary']['border_fraction']['min']:.3f}" in text


def test_the_prisms_code_path_gives_the_cubes_faces_on_the_cube(committed):
    """The control prism (1 + 1e-9) runs the general inertia path from the cube's points: nearly every face is the
    cube's (the rest within what f at the smallest scale allows), and so is its map."""
    c = committed["control"]
    assert c["offset"] == pytest.approx(sa.CONTROL - 1) and c["seed"] == committed["by"]["1"]["seed"]
    assert c["agrees_with_cube"]["agreement"] >= 0.95 and c["agrees_with_cube"]["map_agreement"] >= 0.95
    with np.load(COMMITTED / "maps.npz") as z:
        assert np.mean(z["c_control"] == z["c_1"]) == pytest.approx(c["agrees_with_cube"]["map_agreement"])


def test_the_square_faces_come_up_more_on_the_flat_prism_than_on_the_tall_one(committed):
    """A flat prism (c < 1) rests on its square faces more often than a tall one (c > 1), in the window too."""
    by = committed["by"]
    flat, tall = by["0.8"]["square_faces"], by["1.25"]["square_faces"]
    assert flat["ci_low"] > tall["ci_high"]


def test_the_committed_results_fill_the_report_section(committed):
    text, missing = report.render(report.titled_section("Real dice III"), {"aspect": committed})
    assert not missing and "n/a" not in text
    assert sa.SENTENCES["answer"](committed) in (REPO / "analysis" / "REPORT.md").read_text()


def test_the_report_leaves_out_a_section_whose_study_has_no_results(tmp_path, committed):
    """Built from the writeup studies' results alone, the report has no section of bars or aspect; with their
    folders beside results/ it has both, with no placeholder left."""
    if not (REPO / "analysis" / "results" / "run_all.json").exists():
        pytest.skip("no committed writeup results here")
    shutil.copytree(REPO / "analysis" / "results", tmp_path / "results")
    text = report.build(tmp_path).read_text()
    assert "## Real dice II" not in text and "## Real dice III" not in text and "n/a" not in text
    for name in report.FOLDER_STUDIES:
        (tmp_path / name).mkdir()
        shutil.copy2(REPO / "analysis" / name / "results.json", tmp_path / name)
    text = report.build(tmp_path).read_text()
    assert "## Real dice II:" in text and "## Real dice III:" in text and "{{" not in text
    assert text.index("## Real dice III") < text.index("## Method notes and limits")


@pytest.mark.slow
@pytest.mark.long
def test_the_quick_run_writes_every_file_the_report_reads(tmp_path, dicetrace_cli):
    res = dicetrace_cli("analyze", "aspect", "--quick", "--quiet", "--threads", "1", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    out = tmp_path / "dicetrace-results" / "aspect"
    for name in ("aspect.csv", "results.json", "aspect.md", "aspect.png", "maps.npz"):
        assert (out / name).stat().st_size > 0
    data = json.loads((out / "results.json").read_text())
    assert list(data["by"]) == [f"{c:g}" for c in sa.QUICK["aspects"]]
    for m in data["by"].values():
        assert len(m["f"]) == len(sa.QUICK["eps_rel"]) and all(0 <= f <= 1 for f in m["f"])
        assert math.isclose(sum(m["points"]["faces"]) / m["n_points"] + (m["points"]["edge"] + m["points"]["unsettled"])
                            / m["n_points"], 1.0)
    text, missing = report.render(report.titled_section("Real dice III"), {"aspect": data})
    assert not missing, missing
    assert data["control"]["agrees_with_cube"]["agreement"] >= 0.9  # the general path on the cube: the cube's faces
    sa.rerender(out)
    assert json.loads((out / "results.json").read_text())["summary"] == data["summary"]


def test_bad_input_is_one_line(tmp_path, dicetrace_cli):
    res = dicetrace_cli("analyze", "aspect", "--threads", "0", "--out", str(tmp_path / "x"), cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.strip().count("\n") == 0 and "--threads" in res.stderr
    assert not (tmp_path / "x").exists()
    res = dicetrace_cli("analyze", "aspect", "--n", "5", cwd=tmp_path)
    assert res.returncode == 2 and "--n" in res.stderr
