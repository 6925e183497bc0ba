"""The studies run from an installed (not editable) package, from a folder outside the repository.

``pip install`` of the package's sources with the studies' extra (``analysis``;
``pyproject.toml``, ``README.md`` and ``src/``, copied, so that the build
leaves nothing in the checkout and nothing else of the repository is at hand)
into a fresh virtual environment; then,
through the installed entry point and with a temporary folder as the current
directory, ``dicetrace analyze all --quick --out DIR``, ``dicetrace accuracy
--quick --out DIR`` (the alias), a small ``dicetrace analyze stability --quick``,
``dicetrace analyze friction --quick`` and a study
without ``--out`` (default ``./dicetrace-results/<study>``): nothing may come
from the source tree.  One test, so that parallel workers do not install
twice.  It takes 5–15 minutes on 2 cores (the install, and numba compiling
every kernel afresh in the new environment), more than the whole CI suite
may, so it runs only when ``DICETRACE_INSTALL_TEST=1`` is set (a release
check: ``DICETRACE_INSTALL_TEST=1 pytest tests/studies/test_installed.py``).
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
from pathlib import Path

import pytest

from dicetrace.studies import WRITEUP_STUDIES
from fresh_install import install_sources

REPO = Path(__file__).resolve().parents[2]


def _run(args, cwd, env, timeout=1800):
    proc = subprocess.run([str(a) for a in args], capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout)
    assert proc.returncode == 0, (args, proc.stdout[-3000:] + proc.stderr[-3000:])
    return proc


def _check_analyze(out: Path) -> None:
    names = {p.stem for p in (out / "results").glob("*.json")}
    assert names == {*WRITEUP_STUDIES, "run_all"}
    topo = json.loads((out / "results" / "topology.json").read_text())
    assert all(t["matches_program"] is True for t in topo["throws"])
    report = (out / "REPORT.md").read_text()
    assert report.startswith("> **Quick run.**") and "{{" not in report
    assert (out / "figures" / "i_redsea_z.gif").stat().st_size > 0


def _check_accuracy(out: Path) -> None:
    for name in ("study.csv", "orders.csv", "reference.csv", "presets.json", "work_precision.png", "summary.md"):
        assert (out / name).stat().st_size > 0, name
    with open(out / "study.csv") as f:
        rows = list(csv.DictReader(f))
    assert {r["preset"] for r in rows} == {"seed", "physical"}
    assert all(0.0 <= float(r["outcome_agreement"]) <= 1.0 for r in rows)


@pytest.mark.slow
@pytest.mark.skipif(
    os.environ.get("DICETRACE_INSTALL_TEST") != "1",
    reason="a 5-15 min release check: set DICETRACE_INSTALL_TEST=1 to install the package afresh and run the studies",
)
def test_installed_package_runs_the_studies_from_any_folder(tmp_path):
    py, exe, src, env = install_sources(tmp_path, "analysis")  # the writeup studies need the analysis extra
    work = tmp_path / "elsewhere"
    work.mkdir()

    where = Path(_run([py, "-c", "import dicetrace.studies as s; print(s.__file__)"], work, env).stdout.strip())
    assert "site-packages" in where.parts and REPO not in where.resolve().parents and src not in where.parents

    _run([exe, "analyze", "all", "--quick", "--out", work / "analysis-out"], work, env)
    _check_analyze(work / "analysis-out")
    _run([exe, "accuracy", "--quick", "--quiet", "--out", work / "accuracy-out"], work, env)
    _check_accuracy(work / "accuracy-out")
    _run([exe, "analyze", "stability", "--quick", "--quiet", "--integrator", "semi-implicit-euler", "--presets", "seed",
          "--out", work / "stability-out"], work, env)
    assert "semi-implicit-euler" in (work / "stability-out" / "stability.md").read_text()
    _run([exe, "analyze", "friction", "--quick", "--quiet", "--out", work / "friction-out"], work, env)
    assert "Command: `dicetrace analyze friction --quick --quiet --out " in (work / "friction-out" / "v_reg.md").read_text()
    assert sorted(p.name for p in work.iterdir()) == ["accuracy-out", "analysis-out", "friction-out", "stability-out"]
    # without --out: the working folder ./dicetrace-results/<study>
    _run([exe, "analyze", "wedge", "--quick"], work, env)
    assert (work / "dicetrace-results" / "analysis" / "results" / "wedge.json").exists()
