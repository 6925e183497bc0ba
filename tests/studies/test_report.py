"""``REPORT.md``: the whole report once every writeup study has results, else only the sections of those that have.

A single study (``dicetrace analyze settle --quick``) writes a report of its own section, with its real numbers,
no placeholder, no ``n/a`` and no claim about a full run; with every study's results the report is the whole
template, byte for byte what the committed ``analysis/REPORT.md`` is.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from dicetrace.studies import LETTERS, WRITEUP_STUDIES
from dicetrace.studies.report import FOLDER_STUDIES, build, sections, template_text

REPO = Path(__file__).resolve().parents[2]
COMMITTED = REPO / "analysis"
needs_committed = pytest.mark.skipif(not (COMMITTED / "results" / "run_all.json").exists(),
                                     reason="no committed results here")
LETTER = {name: letter for letter, name in LETTERS.items()}


def _results_of(tmp_path: Path, studies) -> Path:
    """A folder holding the committed results of ``studies`` only."""
    (tmp_path / "results").mkdir()
    for name in studies:
        shutil.copy2(COMMITTED / "results" / f"{name}.json", tmp_path / "results")
    return tmp_path


def _headings(text: str) -> set[str]:
    return {line[3] for line in text.splitlines() if line.startswith("## ") and line[4:5] == "."}


def test_every_study_has_its_section():
    assert set(sections(template_text())) == set(WRITEUP_STUDIES)


@needs_committed
def test_with_every_result_the_report_is_the_whole_template(tmp_path, capsys):
    """The full run's report is unchanged: built from the committed results it is the committed REPORT.md."""
    shutil.copytree(COMMITTED / "results", tmp_path / "results")
    for name in FOLDER_STUDIES:  # the studies run alone whose sections the report carries, beside results/
        if (COMMITTED / name / "results.json").exists():
            (tmp_path / name).mkdir()
            shutil.copy2(COMMITTED / name / "results.json", tmp_path / name)
    text = build(tmp_path).read_text()
    assert text == (COMMITTED / "REPORT.md").read_text()
    assert "placeholder" not in capsys.readouterr().err


@needs_committed
@pytest.mark.parametrize("study", WRITEUP_STUDIES)
def test_one_study_alone_writes_its_own_section_with_every_value(tmp_path, capsys, study):
    out = _results_of(tmp_path, [study])
    text = build(out).read_text()
    err = capsys.readouterr().err
    assert "placeholder" not in err, err
    assert "{{" not in text and "n/a" not in text
    assert _headings(text) == {LETTER[study]}
    assert "The full run took" not in text and "Answers to the writeup" not in text
    assert f"({LETTER[study]} ({study}, " in text  # the header names what ran


@needs_committed
def test_two_studies_write_their_two_sections(tmp_path, capsys):
    out = _results_of(tmp_path, ["settle", "wedge", "run_all"])  # run_all: the full run's timings, not quoted
    text = build(out).read_text()
    assert _headings(text) == {"g", "h"} and "{{" not in text and "n/a" not in text
    assert "The full run took" not in text
    settle = json.loads((out / "results" / "settle.json").read_text())
    assert f"{settle['predicted']['fixed_pivot_per_s']:.2f} /s" in text
    assert "placeholder" not in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.long
def test_analyze_settle_quick_writes_its_own_section(tmp_path):
    """The issue's reproducer: ``dicetrace analyze settle --quick`` into a new folder."""
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "dicetrace.cli", "analyze", "settle", "--quick", "--out", str(out)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "placeholder" not in proc.stderr, proc.stderr
    text = (out / "REPORT.md").read_text()
    assert text.startswith("> **Quick run.**")
    assert "## g. Settle time at the borders" in text and _headings(text) == {"g"}
    assert "{{" not in text and "n/a" not in text
    assert "The full run took" not in text and "full run took" not in text
    res = json.loads((out / "results" / "settle.json").read_text())
    assert f"λ = √(3g/(2√2·s)) = {res['predicted']['fixed_pivot_per_s']:.2f} /s" in text  # real values of this run
    assert f"each of {res['runs']['seed']['summary']['n_fits']:d} border sides" in text
    assert "![g_settle_divergence](figures/g_settle_divergence.png)" in text
    assert (out / "figures" / "g_settle_divergence.png").exists()
