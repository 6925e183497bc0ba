"""The one ``dicetrace analyze all --quick`` run that the studies' tests share.

It is the quick run of the writeup studies (~2 min on two cores; the ``long`` tier): ``test_studies.py`` checks its
outputs, ``test_referee.py`` its study k and ``test_converged.py`` its study l.  With ``pytest -n``
every worker that reaches one of those tests asks for it: the first runs it into the run's common
temporary folder under a file lock, the others wait for it there and read the same outputs
(pytest-xdist's recipe for a session fixture that runs once; its ``loadgroup`` distribution
cannot keep the tests on one worker with pytest 9, whose node ids it no longer rewrites).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest
from filelock import FileLock


@pytest.hookimpl(tryfirst=True)  # before ``-m "not slow"`` and ``-m "not long"`` deselect
def pytest_collection_modifyitems(items):
    """Every test that reads the shared quick run (two minutes of studies on two cores) is ``long`` and ``slow``,
    whether or not it says so: CI's tier leaves it to ``scripts/test.sh --all``."""
    for item in items:
        if "quick_run" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.slow)
            item.add_marker(pytest.mark.long)


@pytest.fixture(scope="session")
def quick_run(tmp_path_factory):
    """(output folder, {study: results JSON}) of ``dicetrace analyze all --quick``, run from a folder
    outside the repository into the default output folder, once per test run."""
    base = tmp_path_factory.getbasetemp()
    here = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "analyze-all-quick"  # workers: one folder
    with FileLock(f"{here}.lock"):
        if not (here / "exit_code").exists():
            here.mkdir(parents=True, exist_ok=True)
            proc = subprocess.run([sys.executable, "-m", "dicetrace.cli", "analyze", "all", "--quick"], cwd=here,
                                  capture_output=True, text=True, timeout=900)
            (here / "log.txt").write_text(proc.stdout[-3000:] + proc.stderr[-3000:])
            (here / "exit_code").write_text(str(proc.returncode))
    assert (here / "exit_code").read_text() == "0", (here / "log.txt").read_text()
    out = here / "dicetrace-results" / "analysis"  # the default output folder
    results = {p.stem: json.loads(p.read_text()) for p in (out / "results").glob("*.json")}
    return out, results


@pytest.fixture(scope="session")
def copy_of_study(quick_run, tmp_path_factory):
    """``copy_of_study(name)``: (a folder, its results) holding one study's part of the shared quick run, its
    results JSON and the figures, copied so that a test may rerender into it without touching what others read."""
    shared, results = quick_run

    def copy(name: str):
        out = tmp_path_factory.mktemp(name) / "out"
        (out / "results").mkdir(parents=True)
        shutil.copy(shared / "results" / f"{name}.json", out / "results")
        shutil.copytree(shared / "figures", out / "figures")
        return out, results[name]

    return copy
