"""The release checks' new environment: the package's sources, copied (so that the build leaves nothing in the
checkout and nothing else of the repository is at hand), ``pip install``-ed with an extra or none into a new
virtual environment, from the package index pip is set up for (skipped where there is none)."""

from __future__ import annotations

import os
import shutil
import subprocess
import venv
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def install_sources(tmp_path: Path, extra: str | None = None) -> tuple[Path, Path, Path, dict]:
    """(python, the dicetrace script, the copied sources, an environment without this checkout on its path)."""
    src = tmp_path / "source"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, src / name)
    shutil.copytree(REPO / "src", src / "src", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "*.nbi", "*.nbc"))
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    py, exe = env_dir / "bin" / "python", env_dir / "bin" / "dicetrace"
    target = str(src) + (f"[{extra}]" if extra else "")
    proc = subprocess.run([str(py), "-m", "pip", "install", "-q", target], capture_output=True, text=True,
                          timeout=1800, cwd=tmp_path)
    if proc.returncode != 0 and "No matching distribution" in proc.stderr:
        pytest.skip("the dependencies cannot be installed here (no package index)")
    assert proc.returncode == 0, proc.stderr[-3000:]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return py, exe, src, env
