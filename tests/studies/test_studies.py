"""The studies of ``analysis/``: ``run_all.py --quick`` into a temporary folder, outputs and numbers checked.

This is the CI run of the studies (CI-sized grids); the full run is
``python analysis/run_all.py`` and takes minutes.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
ANALYSIS = REPO / "analysis"
STUDIES = ("cells", "fractal", "repetition", "topology", "damping", "vertices", "settle", "wedge", "animation")
MAX_FIGURE_BYTES = 300_000

pytestmark = pytest.mark.skipif(not (ANALYSIS / "run_all.py").exists(), reason="analysis/ folder not present")


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("studies")
    proc = subprocess.run(
        [sys.executable, str(ANALYSIS / "run_all.py"), "--quick", "--out", str(out)],
        cwd=out, capture_output=True, text=True, timeout=900,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    results = {p.stem: json.loads(p.read_text()) for p in (out / "results").glob("*.json")}
    return out, results, proc


def test_every_study_wrote_results_and_figures(quick_run):
    out, results, _ = quick_run
    for name in STUDIES:
        assert name in results, f"no results/{name}.json"
        r = results[name]
        assert r["quick"] is True
        assert r["figures"], f"{name} drew no figure"
        for key, fig in r["figures"].items():
            p = out / fig["path"]
            assert p.exists(), p
            assert 0 < p.stat().st_size < MAX_FIGURE_BYTES, (p, p.stat().st_size)
    timing = results["run_all"]
    assert set(timing["timings_s"]) == set(STUDIES)
    assert timing["total_s"] > 0


def test_report_is_assembled(quick_run):
    out, _, _ = quick_run
    text = (out / "REPORT.md").read_text()
    assert text.startswith("> **Quick run.**")
    for name in ("figures/a_zoom_ladder.png", "figures/g_settle_divergence.png", "figures/i_redsea_z.gif"):
        assert name in text
    assert "{{" not in text


def test_numbers_are_sane(quick_run):
    _, R, _ = quick_run
    for w, d in R["cells"]["windows"].items():
        fr = d["fractions"]
        assert sum(f["fraction"] for f in fr) == pytest.approx(1.0)
        assert all(f["ci_low"] <= f["fraction"] <= f["ci_high"] for f in fr)
        assert 1 <= d["cells"]["n_cells"] <= d["cells"]["n_nodes"]
    for w, d in R["fractal"]["windows"].items():
        assert 0.0 <= d["boundary_fraction"] <= 1.0
        assert 0.0 <= d["Sb"] <= math.log(6) + 1e-9
        assert d["Sbb"] is None or 0.0 < d["Sbb"] <= math.log(6) + 1e-9
        assert d["dimension"] == pytest.approx(2.0 - d["alpha"])
    throws = R["topology"]["throws"]
    assert [t["outcome"] for t in throws] == [3, 3, 3]
    assert all(t["matches_program"] in (True, None) for t in throws)
    assert not any(p["same"] for p in R["topology"]["pairs"])  # the writeup: topologically different
    assert R["topology"]["cell"]["n_sequences"] >= 1
    for f in R["wedge"]["fits"]:  # the fit recovers the ball-hill saddle rate sqrt(g/R)
        assert f["lambda"] == pytest.approx(R["wedge"]["saddle_rate_per_s"], rel=0.01)
    assert R["settle"]["predicted"]["fixed_pivot_per_s"] == pytest.approx(22.797, abs=1e-3)
    assert [row["gamma"] for row in R["damping"]["sweep"]] == [0.0025, 0.005, 0.01, 0.02]
    for row in R["damping"]["sweep"]:
        assert 0.0 <= row["boundary_fraction"] <= 1.0
    assert len(R["animation"]["frame_change_fraction"]) == R["animation"]["res"][2] - 1
    assert R["vertices"]["hunts"]


def test_cli_runs_one_study(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "dicetrace.cli", "analyze", "wedge", "--quick", "--out", str(tmp_path)],
        cwd=REPO, capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "results" / "wedge.json").exists()
    assert (tmp_path / "figures" / "h_ball_hill.png").exists()
    assert (tmp_path / "REPORT.md").exists()


def test_cli_rejects_an_unknown_study(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "dicetrace.cli", "analyze", "nonsense", "--out", str(tmp_path)],
        cwd=REPO, capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2
    assert "unknown study" in proc.stderr
