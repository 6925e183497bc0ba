"""``dicetrace analyze accuracy``: the work-precision study (quick size, default output folder) and its pieces."""

from __future__ import annotations

import csv
import subprocess
import sys

import numpy as np
import pytest

from dicetrace.params import INTEGRATORS, make_config
from dicetrace.status import Status
from dicetrace.studies import study_accuracy as acc
from dicetrace.studies.study_accuracy_grids import GRIDS, color, grid


@pytest.mark.slow
@pytest.mark.long
def test_quick_study_cli_runs(tmp_path):
    """No --out: the results go to ./dicetrace-results/accuracy of the current folder (a bounded wait, no time
    assert: speed belongs in benchmarks/); the summary names the command as typed."""
    res = subprocess.run(
        [sys.executable, "-m", "dicetrace.cli", "analyze", "accuracy", "--quick", "--quiet"],
        capture_output=True, text=True, timeout=600, cwd=tmp_path,
    )
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dicetrace-results"]
    assert "wrote dicetrace-results/accuracy/summary.md" in res.stdout
    tmp_path = tmp_path / "dicetrace-results" / "accuracy"
    assert "Command: `dicetrace analyze accuracy --quick --quiet`" in (tmp_path / "summary.md").read_text()
    for name in ("study.csv", "orders.csv", "reference.csv", "work_precision.png", "summary.md"):
        assert (tmp_path / name).stat().st_size > 0
    with open(tmp_path / "study.csv") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(acc.STUDY_COLUMNS)
    # every preset × integrator × quick step (× quick tolerance, uniform or growing, for an error-controlled one)
    per_preset = sum(len(GRIDS[n].quick_dt_s) * max(1, (len(GRIDS[n].quick_tol) + len(GRIDS[n].quick_graded))
                                                    * s.adaptive)
                     for n, s in INTEGRATORS.items())
    assert len(rows) == 2 * per_preset
    assert any(g.quick_graded for g in GRIDS.values())
    for name, spec in INTEGRATORS.items():
        mine = [r for r in rows if r["integrator"] == name]
        grid = GRIDS[name]
        assert {float(r["dt_s"]) for r in mine} == set(grid.quick_dt_s)
        if spec.adaptive:
            settings = {(float(r["tol"]), float(r["tol_growth"])) for r in mine}
            assert settings == {(t, 0.0) for t in grid.quick_tol} | {(t, g) for g, t in grid.quick_graded}
        else:
            assert all(r["tol"] in ("", "nan") and r["tol_growth"] in ("", "nan") for r in mine)
    for r in rows:
        assert 0.0 <= float(r["outcome_agreement"]) <= 1.0
        assert float(r["cpu_ms_per_ic"]) > 0
        for rel in ("1e-12", "1e-09", "1e-06"):
            assert 0.0 <= float(r[f"chaos_floor_{rel}"]) <= 1.0
        assert int(r["own_floor_n"]) == acc.QUICK_FLOOR_N and 0 <= int(r["own_floor_flips"]) <= acc.QUICK_FLOOR_N
    with open(tmp_path / "reference.csv") as f:
        refs = list(csv.DictReader(f))
    assert [r["preset"] for r in refs] == list(acc.PRESETS)
    for r in refs:
        assert r["second_reference"] == acc.QUICK_SECOND_REFERENCE.label
        lo, frac, hi = (float(r[k]) for k in ("references_agreement_lo", "references_agreement", "references_agreement_hi"))
        assert 0.0 <= lo <= frac <= hi <= 1.0
    text = (tmp_path / "summary.md").read_text()
    assert "Best method for a time budget" in text and "chaos floor" in text.lower()
    assert "## Own numerical floor of each setting" in text and "settings whose floor is 0" in text
    assert "## Cheapest setting of each integrator at the target agreement" in text


@pytest.mark.slow
@pytest.mark.long
def test_bad_input_is_one_line_exit_2(tmp_path):
    for args in (["--window", "nowhere"], ["--n", "1"], ["--integrator", "euler"], ["--presets", "seed,x"]):
        res = subprocess.run(
            [sys.executable, "-m", "dicetrace.cli", "accuracy", *args, "--out", str(tmp_path)],
            capture_output=True, text=True, timeout=300,
        )
        assert res.returncode == 2, (args, res.stderr)
        assert res.stderr.startswith("dicetrace: error:") and res.stderr.count("\n") == 1


def test_sample_is_seeded_and_in_the_window():
    a = acc.sample_ics("red-sea", 50, seed=3)
    b = acc.sample_ics("red-sea", 50, seed=3)
    np.testing.assert_array_equal(a, b)
    from dicetrace.ics import SEED_SLICE

    # the slice is affine: recover coordinates from U (2 directions, least squares)
    d = np.array(SEED_SLICE.directions)[:, :3].T
    xy = np.linalg.lstsq(d, a[:, :3].T, rcond=None)[0].T
    assert np.all((xy[:, 0] >= 1.0 - 1e-9) & (xy[:, 0] <= 2.0 + 1e-9))
    assert np.all((xy[:, 1] >= 3.5 - 1e-9) & (xy[:, 1] <= 4.5 + 1e-9))


def test_perturbation_has_the_stated_relative_size():
    ics = acc.sample_ics("zoom-out", 20, seed=0)
    for rel in acc.PERTURBATIONS:
        p = acc.perturb(ics, rel, seed=0)
        r = np.linalg.norm(p - ics, axis=1) / np.linalg.norm(ics, axis=1)
        np.testing.assert_allclose(r, rel, rtol=1e-3)  # rounding of the sum at 1e-12


def test_every_integrator_has_a_study_grid_and_a_colour():
    """The study's grids cover the integrator table, one distinct colour each; tolerances only for adaptive ones."""
    assert list(GRIDS) == list(INTEGRATORS)
    assert len({g.color for g in GRIDS.values()}) == len(GRIDS)
    for name, spec in INTEGRATORS.items():
        g = grid(name)
        assert color(name) == g.color and g.study_dt_s and g.quick_dt_s
        assert bool(g.study_tol) == spec.adaptive and bool(g.quick_tol) == spec.adaptive
        assert not (g.study_graded or g.quick_graded) or spec.adaptive
    with pytest.raises(ValueError, match="no study grid"):
        grid("nope")


def test_horizon_is_on_every_grid():
    h = acc.first_impact_horizon(0.1713)
    assert h >= 0.1713 + acc.FIRST_IMPACT_AFTER_S
    steps = [g.study_dt_s + g.quick_dt_s for g in GRIDS.values()]
    for dts in steps + [[acc.REFERENCE.dt_s, acc.REFERENCE.check_dt_s]]:
        for dt in dts:
            n = h / dt
            assert abs(n - round(n)) < 1e-9


def test_agreement_counts_unsettled_as_disagreement():
    settled = int(Status.SETTLED)
    ref = acc.Runs(np.array([1, 2, 3]), np.array([settled] * 3), np.zeros(3), np.zeros(3, int), np.zeros(3))
    run = acc.Runs(np.array([1, 2, -1]), np.array([settled, settled, int(Status.BLOW_UP)]), np.zeros(3),
                   np.zeros(3, int), np.zeros(3))
    assert acc.agreement(run, ref) == pytest.approx(2 / 3)


def test_study_runs_come_from_the_integrator_table():
    """The steps and tolerances of a study run are its grid's, nothing else."""
    adaptive = next(n for n, s in INTEGRATORS.items() if s.adaptive)
    spec = GRIDS[adaptive]
    assert acc.study_runs(adaptive) == ([(dt, tol, 0.0) for dt in spec.study_dt_s for tol in spec.study_tol]
                                        + [(dt, tol, g) for dt in spec.study_dt_s for g, tol in spec.study_graded])
    assert acc.study_runs("rk4", quick=True) == [(dt, None, None) for dt in GRIDS["rk4"].quick_dt_s]
    # physical's default schedule is one of the study's settings, so the study measures the default
    phys = make_config("physical").numerics
    assert (phys.dt_s, phys.tol, phys.tol_growth) in acc.study_runs(phys.integrator)
    with pytest.raises(ValueError, match="unknown integrator"):
        acc.check_integrators(["euler"])


@pytest.mark.slow
@pytest.mark.long
def test_quick_run_may_not_overwrite_committed_results(tmp_path):
    """A folder holding the committed-results marker takes full runs only; the refusal writes nothing."""
    from dicetrace.studies.outputs import COMMITTED_MARKER

    (tmp_path / COMMITTED_MARKER).write_text("committed\n")
    target = tmp_path / "accuracy"
    for cmd in (["accuracy", "--quick"], ["accuracy", "--n", "20"], ["stability", "--quick"], ["stability", "--k", "5e5"]):
        res = subprocess.run([sys.executable, "-m", "dicetrace.cli", *cmd, "--out", str(target)],
                             capture_output=True, text=True, timeout=300)
        assert res.returncode == 2, (cmd, res.stderr)
        assert "committed full-run results" in res.stderr and res.stderr.count("\n") == 1
        assert not target.exists()


def test_own_floor_counts_flips_of_the_setting_itself():
    """No perturbation: no flip (runs are deterministic); a large one on a chaotic window: flips."""
    from dicetrace.params import make_config

    cfg = make_config("seed", t_max_s=acc.T_MAX_S)
    ics = acc.sample_ics("zoom-out", 20, seed=0)
    assert acc.own_floor(ics, cfg, 0, rel=0.0) == 0
    assert acc.own_floor(ics, cfg, 0, rel=0.2) > 0


def test_a_setting_names_its_tolerance_growth():
    """A run whose tolerance loosens over the throw is told apart from the uniform one everywhere it is named."""
    from dicetrace.studies.study_accuracy_render import _settings_text, setting

    uniform = {"integrator": "contact-tsit5", "dt_s": 1e-3, "tol": 2e-8, "tol_growth": 0.0}
    graded = dict(uniform, tol_growth=10.0)
    fixed = {"integrator": "rk4", "dt_s": 1e-3, "tol": float("nan"), "tol_growth": float("nan")}
    assert setting(uniform) == "dt = 0.001 s, tol = 2e-08"
    assert setting(graded) == "dt = 0.001 s, tol = 2e-08 growing 10/s"
    assert setting(fixed) == "dt = 0.001 s"
    assert _settings_text([uniform, graded, fixed]) == (
        "contact-tsit5 at dt = 0.001 s, tol = 2e-08, 2e-08 growing 10/s; rk4 at dt = 0.001 s")
