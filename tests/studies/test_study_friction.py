"""The friction-regularisation study (``dicetrace analyze friction``), quick size."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from dicetrace.studies import study_friction as fr


@pytest.mark.slow
def test_quick_study_writes_its_tables(tmp_path, dicetrace_cli):
    """--quick: 8 ICs, v_reg 10 and 3 cm/s, two tolerances; every run is in the CSV, every
    throw settles and is counted in the faces, and agreement is 1 for a run with itself."""
    res = dicetrace_cli("analyze", "friction", "--quick", "--quiet", "--out", "fr", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines() == ["wrote fr/v_reg.csv", "wrote fr/v_reg.md"]
    tmp_path = tmp_path / "fr"
    with open(tmp_path / "v_reg.csv") as f:
        rows = list(csv.DictReader(f))
    q = fr.QUICK
    assert len(rows) == len(q["v_regs"]) * (len(q["tols"]) + 1)
    assert {r["integrator"] for r in rows} == {"contact-dop853", "contact-adaptive"}
    for r in rows:
        assert int(r["unsettled"]) == 0
        assert sum(int(r[f"face_{k}"]) for k in range(1, 7)) == q["n"]
        assert 0.0 <= float(r["agreement_ci_low"]) <= float(r["agreement_with_tightest"]) <= float(r["agreement_ci_high"]) <= 1.0
        assert float(r["cpu_ms_per_throw"]) > 0
    tightest = [r for r in rows if r["integrator"] == "contact-dop853" and float(r["tol"]) == q["tols"][-1]]
    assert [float(r["agreement_with_tightest"]) for r in tightest] == [1.0] * len(q["v_regs"])
    text = (tmp_path / "v_reg.md").read_text()
    assert "Command: `dicetrace analyze friction --quick --quiet --out fr`" in text
    assert "| 10 | yes |" in text or "| 10 | no |" in text
    assert text.rstrip().endswith(fr.IMPLICIT_RESULT)  # the removed implicit scheme's measured result, kept


def test_summary_marks_unconverged_and_compares_faces():
    """summarise: converged needs both the self and the independent agreement; the χ² test
    compares each v_reg's faces with the first (50 each against 100, 20, 50, 50, 50, 30: p ≈ 2e-6)."""
    def row(v, integ, tol, agree, faces):
        return {"v_reg_cm_s": v, "integrator": integ, "tol": tol, "agreement_with_tightest": agree,
                "cpu_ms_per_throw": 1.0 / tol ** 0.1, "mean_settle_time_s": 1.0,
                **{f"face_{k}": faces[k - 1] for k in range(1, 7)}}
    faces = [50, 50, 50, 50, 50, 50]
    rows = [row(10, "contact-dop853", 1e-6, 0.95, faces), row(10, "contact-dop853", 1e-7, 0.99, faces),
            row(10, "contact-dop853", 1e-8, 1.0, faces), row(10, "contact-adaptive", 1e-8, 0.96, faces),
            row(1, "contact-dop853", 1e-6, 0.5, faces), row(1, "contact-dop853", 1e-7, 0.8, faces),
            row(1, "contact-dop853", 1e-8, 1.0, [100, 20, 50, 50, 50, 30]), row(1, "contact-adaptive", 1e-8, 0.97, faces)]
    s = fr.summarise(rows)
    assert s[0]["converged"] and s[0]["cheapest_tol"] == 1e-6
    assert not s[1]["converged"] and np.isnan(s[1]["cost_to_converge_ms"])
    assert np.isnan(s[0]["chi2_p_vs_first"]) and s[1]["chi2_p_vs_first"] < 1e-4
