"""The writeup studies of ``dicetrace.studies``: ``dicetrace analyze all --quick`` into a temporary folder.

This is the CI run of the studies (CI-sized grids), through the command
line, from a folder outside the repository; the outputs and their numbers
are checked.  The full run (``dicetrace analyze all --out analysis``, which
regenerates the committed results) takes minutes.
"""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from pathlib import Path

import pytest

from dicetrace.studies import LETTERS, WRITEUP_STUDIES, resolve

REPO = Path(__file__).resolve().parents[2]
MAX_FIGURE_BYTES = 300_000


def _dicetrace(*args, cwd, timeout=300):
    return subprocess.run([sys.executable, "-m", "dicetrace.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.slow
@pytest.mark.long
def test_every_study_wrote_results_and_figures(quick_run):
    out, results = quick_run
    for name in WRITEUP_STUDIES:
        assert name in results, f"no results/{name}.json"
        r = results[name]
        assert r["quick"] is True and r["study"] == name
        assert r["device"] == "cpu"  # where its batches ran (dicetrace analyze --device)
        assert r["figures"], f"{name} drew no figure"
        for fig in r["figures"].values():
            p = out / fig["path"]
            assert p.exists(), p
            assert 0 < p.stat().st_size < MAX_FIGURE_BYTES, (p, p.stat().st_size)
            assert p.name[0] in LETTERS and LETTERS[p.name[0]] == name  # figures carry their study's letter
    timing = results["run_all"]
    assert set(timing["timings_s"]) == set(WRITEUP_STUDIES)
    assert timing["total_s"] > 0
    with open(out / "results" / "damping_sweep.csv") as f:
        assert [float(r["gamma"]) for r in csv.DictReader(f)] == [0.0025, 0.005, 0.01, 0.02]
    # nothing the run drew warned (an empty legend was once held and printed at the end as a warning)
    log = (out.parent.parent / "log.txt").read_text()
    assert "warning:" not in log, log[log.index("warning:") - 200:][:600]


@pytest.mark.slow
def test_report_is_assembled(quick_run):
    out, _ = quick_run
    text = (out / "REPORT.md").read_text()
    assert text.startswith("> **Quick run.**")
    for name in ("figures/a_zoom_ladder.png", "figures/g_settle_divergence.png", "figures/i_redsea_z.gif"):
        assert name in text
    assert "{{" not in text


@pytest.mark.slow
def test_numbers_are_sane(quick_run):
    _, R = quick_run
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
    assert set(R["fractal"]["extra_windows"]) == {"red-sea-3", "red-sea-4", "party-2", "party-3"}
    throws = R["topology"]["throws"]
    assert [t["outcome"] for t in throws] == [3, 3, 3]
    assert all(t["matches_program"] is True for t in throws)  # bit-exact against the 2019 program
    assert not any(p["same"] for p in R["topology"]["pairs"])  # the writeup: topologically different
    assert R["topology"]["cell"]["n_sequences"] >= 1
    for f in R["wedge"]["fits"]:  # the fit recovers the ball-hill saddle rate sqrt(g/R)
        assert f["lambda"] == pytest.approx(R["wedge"]["saddle_rate_per_s"], rel=0.01)
    assert R["settle"]["predicted"]["fixed_pivot_per_s"] == pytest.approx(22.797, abs=1e-3)
    assert all("profile" not in f and len(f["t_range_s"]) == 2 for f in R["settle"]["runs"]["seed"]["fits"])
    assert [row["gamma"] for row in R["damping"]["sweep"]] == [0.0025, 0.005, 0.01, 0.02]
    for row in R["damping"]["sweep"]:
        assert 0.0 <= row["boundary_fraction"] <= 1.0
    assert len(R["animation"]["frame_change_fraction"]) == R["animation"]["res"][2] - 1
    assert [h["window"] for h in R["vertices"]["hunts"]][:3] == ["party", "green-island", "home"]
    assert len(R["vertices"]["triple_squares"]["rows"]) == 7  # the program's green-island chain


def test_program_throws_are_the_reference_files():
    """The topology study's copy of the program's three throws is rows 1-3 of the reference data."""
    from dicetrace.studies.study_topology import PROGRAM_THROWS

    with open(REPO / "tests" / "data" / "reference" / "writeup_points.csv", newline="") as f:
        rows = list(csv.DictReader(f))[:3]
    got = {(round(float(r["x"]), 6), round(float(r["y"]), 6)): (int(r["outcome"]), int(r["steps"]), r["contact_sequence"])
           for r in rows}
    assert got == PROGRAM_THROWS


def test_resolve_names_and_letters():
    assert resolve(["all"]) == list(WRITEUP_STUDIES)
    assert resolve(["g", "cells", "settle"]) == ["settle", "cells"]
    with pytest.raises(ValueError, match="unknown study"):
        resolve(["accuracy"])  # an integrator study has its own command


@pytest.mark.slow
def test_cli_runs_one_study_and_the_report_alone(tmp_path):
    proc = _dicetrace("analyze", "wedge", "--quick", "--out", str(tmp_path), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "results" / "wedge.json").exists()
    assert (tmp_path / "figures" / "h_ball_hill.png").exists()
    (tmp_path / "REPORT.md").unlink()
    proc = _dicetrace("analyze", "--report-only", "--out", str(tmp_path), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "![h_ball_hill](figures/h_ball_hill.png)" in (tmp_path / "REPORT.md").read_text()


@pytest.mark.slow  # seconds (a subprocess or a long fit): the quick loop skips it, CI runs it
def test_cli_rejects_an_unknown_study(tmp_path):
    proc = _dicetrace("analyze", "nonsense", "--out", str(tmp_path), cwd=tmp_path)
    assert proc.returncode == 2
    assert "unknown study" in proc.stderr


@pytest.mark.slow
@pytest.mark.skipif(not (REPO / "analysis" / ".committed-results").exists(), reason="no committed results here")
@pytest.mark.long
def test_quick_run_never_touches_the_committed_results():
    """``--quick`` (or --res, --seed, --integrator, --tol) into analysis/ is refused before anything is written."""
    before = {p: p.stat().st_mtime_ns for p in (REPO / "analysis").rglob("*") if p.is_file()}
    for args in (["--quick"], ["--res", "21"], ["--seed", "1"], ["--integrator", "contact-adaptive"], ["--tol", "1e-6"]):
        proc = _dicetrace("analyze", "wedge", *args, "--out", "analysis", cwd=REPO)
        assert proc.returncode == 2, (args, proc.stderr)
        assert "committed full-run results" in proc.stderr and proc.stderr.count("\n") == 1
        proc = _dicetrace("analyze", "wedge", *args, "--out", "analysis/figures", cwd=REPO)
        assert proc.returncode == 2, (args, proc.stderr)
    after = {p: p.stat().st_mtime_ns for p in (REPO / "analysis").rglob("*") if p.is_file()}
    assert after == before


def test_a_cached_grid_is_one_of_the_configuration_that_runs_now(tmp_path, monkeypatch):
    """The studies' grid cache keys on the whole resolved configuration: when a preset's default
    changes (here physical's tolerance), a grid cached under the same options is simulated again,
    not read back; with nothing changed it is read back."""
    import dataclasses

    from dicetrace import params
    from dicetrace.studies.context import Context, Options

    ctx = Context("cache", Options(), tmp_path)
    window, res = ((1.0, 1.2), (3.8, 4.0)), 3
    a = ctx.sample(window, res, preset="physical")
    assert ctx.n_throws == 9
    b = ctx.sample(window, res, preset="physical")
    assert ctx.n_throws == 9 and (a.labels == b.labels).all()  # read back
    looser = dataclasses.replace(params.PRESETS["physical"], default_tol=1e-6, default_tol_growth=0.0)
    monkeypatch.setitem(params.PRESETS, "physical", looser)
    ctx.sample(window, res, preset="physical")
    assert ctx.n_throws == 18  # simulated again
    assert len(list(tmp_path.glob("*.npz"))) == 2
