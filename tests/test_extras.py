"""The lean install: the base runs ``simulate``, ``record`` and ``scan`` without any extra, and each feature whose
extra is missing refuses in one line that names it (exit code 2 at the command line, nothing written).

Without the extras: ``dicetrace`` runs in a subprocess whose ``sitecustomize`` puts an import hook first on
``sys.meta_path`` that makes every module of the extras (and what only they bring: Jupyter's kernel stack,
networkx, numba-cuda) unimportable, as if they were not installed; ``importlib.util.find_spec`` fails on them
too.  The hook is checked to bite (``import starlette`` fails under it).

The real thing, opt-in (``DICETRACE_INSTALL_TEST=1``, minutes): ``pip install`` of the package's sources, no
extra, into a new virtual environment (from the package index, as a user would), then ``record`` there, the
refusals, and the list of what got installed.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from dicetrace import extras
from fresh_install import install_sources

REPO = Path(__file__).resolve().parents[1]
#: What the extras bring that the base must not need (top-level module names; click: typer no longer needs it).
BLOCKED = ("starlette", "uvicorn", "rerun_notebook", "anywidget", "ipykernel", "IPython", "ipywidgets",
           "jupyter_ui_poll", "dask", "distributed", "skimage", "networkx", "numba_cuda", "click")
HOOK = '''
import sys
BLOCKED = set({blocked!r})
class _NotInstalled:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None
sys.meta_path.insert(0, _NotInstalled())
'''


def _pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())


def test_every_extra_is_declared_and_all_and_test_pull_them():
    optional = _pyproject()["project"]["optional-dependencies"]
    assert set(extras.EXTRAS) <= set(optional)
    assert optional["all"] == [f"dicetrace[{','.join(extras.EXTRAS)}]"]
    assert "dicetrace[all]" in optional["test"]
    base = " ".join(_pyproject()["project"]["dependencies"])
    for name in ("starlette", "uvicorn", "rerun-notebook", "anywidget", "dask", "scikit-image", "numba-cuda"):
        assert name not in base, name


def test_require_names_the_extra_and_what_is_missing(monkeypatch):
    monkeypatch.setitem(extras.EXTRAS, "explore", ("starlette", "no_such_module_here"))
    with pytest.raises(extras.MissingExtra) as e:
        extras.require("explore", "dicetrace explore")
    assert str(e.value) == ("dicetrace explore needs the explore extra: pip install 'dicetrace[explore]' "
                            "(missing: no_such_module_here)")
    assert isinstance(e.value, ImportError)
    extras.require("analysis", "label_cells")  # installed here: no error


def _env(tmp_path: Path) -> dict:
    hook = tmp_path / "hook"
    hook.mkdir(exist_ok=True)
    (hook / "sitecustomize.py").write_text(HOOK.format(blocked=BLOCKED))
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV",)}
    env["PYTHONPATH"] = os.pathsep.join([str(hook), str(REPO / "src")])
    return env


def _run(args, tmp_path, env):
    return subprocess.run([sys.executable, *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)


def _one_line_naming(res, extra: str) -> None:
    assert res.returncode == 2, (res.returncode, res.stderr[-2000:])
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dicetrace: error: "), res.stderr
    assert f"pip install 'dicetrace[{extra}]'" in lines[0], lines[0]


@pytest.mark.slow
@pytest.mark.long
def test_without_the_extras_record_runs_and_the_explorer_refuses_in_one_line(tmp_path):
    env = _env(tmp_path)
    hooked = _run(["-c", "import starlette"], tmp_path, env)
    assert hooked.returncode != 0 and "No module named 'starlette'" in hooked.stderr  # the hook bites
    res = _run(["-m", "dicetrace", "record", "--slice", "seed", "--at", "1.65,3.9", "--parquet", "out"], tmp_path, env)
    assert res.returncode == 0, res.stderr[-3000:]
    rrd = tmp_path / "recordings" / "seed_x1.65_y3.9.rrd"
    assert rrd.read_bytes()[:4] == b"RRF2" and (tmp_path / "out" / "trajectory.parquet").stat().st_size > 0
    assert "outcome 3" in res.stdout
    res = _run(["-m", "dicetrace", "scan", "--slice", "seed", "--window", "red-sea", "--res", "8", "--out", "scans/s",
                "--png", "out/s.png", "--quiet"], tmp_path, env)
    assert res.returncode == 0 and (tmp_path / "out" / "s.png").stat().st_size > 0, res.stderr[-3000:]

    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if "hook" not in p.parts)
    _one_line_naming(_run(["-m", "dicetrace", "explore", "--no-browser"], tmp_path, env), "explore")
    _one_line_naming(_run(["-m", "dicetrace", "record", "--slice", "seed", "--at", "1.6,3.9", "--serve"],
                          tmp_path, env), "explore")
    _one_line_naming(_run(["-m", "dicetrace", "scan", "--slice", "seed", "--window", "red-sea", "--res", "8",
                           "--out", "scans/d", "--dask"], tmp_path, env), "dask")
    _one_line_naming(_run(["-m", "dicetrace", "analyze", "cells", "--quick", "--out", "results"], tmp_path, env),
                     "analysis")
    after = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if "hook" not in p.parts)
    assert after == before  # a refusal writes nothing


@pytest.mark.slow
def test_without_the_extras_the_python_api_refuses_naming_the_extra(tmp_path):
    script = """
import numpy as np
from dicetrace.extras import MissingExtra
from dicetrace.ics import Grid
from dicetrace.scan import scan
from dicetrace.analysis import label_cells
from dicetrace.explore import Explorer
said = []
for what, call in [("dask", lambda: scan(Grid("seed", "red-sea", 4), "scans/x", dask=True)),
                   ("analysis", lambda: label_cells(np.zeros((3, 3), int))),
                   ("explore", lambda: Explorer().start())]:
    try:
        call()
    except MissingExtra as e:
        assert f"pip install 'dicetrace[{what}]'" in str(e), e
        said.append(what)
print(" ".join(said))
"""
    res = _run(["-c", script], tmp_path, _env(tmp_path))
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.split() == ["dask", "analysis", "explore"]
    assert not (tmp_path / "scans").exists()


@pytest.mark.slow
@pytest.mark.skipif(os.environ.get("DICETRACE_INSTALL_TEST") != "1",
                    reason="minutes: set DICETRACE_INSTALL_TEST=1 to pip install the base into a new environment")
def test_the_base_install_records_and_refuses_the_explorer(tmp_path):
    py, exe, _, env = install_sources(tmp_path)  # the base: no extra
    work = tmp_path / "work"
    work.mkdir()
    installed = subprocess.run([str(py), "-m", "pip", "list", "--format=freeze"], capture_output=True, text=True,
                               env=env, check=True).stdout.lower()
    for dist in ("starlette", "uvicorn", "rerun-notebook", "anywidget", "ipykernel", "dask", "distributed",
                 "scikit-image", "networkx", "numba-cuda"):
        assert f"\n{dist}==" not in "\n" + installed, dist
    res = subprocess.run([str(exe), "record", "--slice", "seed", "--at", "1.65,3.9"], cwd=work, env=env,
                         capture_output=True, text=True, timeout=1800)
    assert res.returncode == 0, res.stderr[-3000:]
    assert (work / "recordings" / "seed_x1.65_y3.9.rrd").read_bytes()[:4] == b"RRF2"
    res = subprocess.run([str(exe), "explore", "--no-browser"], cwd=work, env=env, capture_output=True, text=True,
                         timeout=600)
    _one_line_naming(res, "explore")


def test_the_readme_quotes_the_measured_install_sizes():
    import json

    measured = json.loads((REPO / "benchmarks" / "results" / "install_sizes.json").read_text())
    rows = {r["extra"]: r for r in measured["installs"]}
    readme = (REPO / "README.md").read_text()
    table = {m.group(1): m.group(0) for m in re.finditer(r"^\| `(?:pip install -e )?'?\.(?:\[(\w+)\])?'?` \|.*$",
                                                              readme, re.M)}
    assert f"{rows['base']['disk_mib']:.0f} MiB, {rows['base']['distributions']} packages" in table[None]
    for extra in ("explore", "jupyter", "dask", "analysis", "all"):
        assert f"+{rows[extra]['adds_mib']:.0f} MiB" in table[extra], extra
    assert f"({rows['all']['disk_mib']:.0f} MiB in all)" in table["all"]
    assert measured["date"] in readme
