"""The on-disk kernel cache is keyed by what kernels compile in (``core._jit``)."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import dicetrace.core
from dicetrace import params
from dicetrace.core import _jit

CORE = Path(dicetrace.core.__file__).resolve().parent


def _constants_core_imports_from_params() -> set[str]:
    """Names that a module of dicetrace.core imports from dicetrace.params and that are plain values."""
    names = set()
    for path in CORE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module == "dicetrace.params":
                names |= {a.name for a in node.names}
    return {n for n in names if isinstance(getattr(params, n), (int, float, str, tuple, np.ndarray))}


def test_core_imports_some_constants_from_params():
    assert {"FRICTION_SPECTRAL", "TOL_LOOSEST"} <= _constants_core_imports_from_params()


@pytest.mark.parametrize("name", sorted(_constants_core_imports_from_params()))
def test_a_constant_that_kernels_compile_in_keys_the_cache(name, monkeypatch):
    """Numba freezes a module global into the compiled kernel: changing one that core imports from params
    must change the digest that stamps the cached kernels, or a stale kernel would be loaded."""
    before = _jit._core_digest()
    value = getattr(params, name)
    changed = value + 1 if not isinstance(value, np.ndarray) else value + 1.0
    monkeypatch.setattr(params, name, changed)
    assert _jit._core_digest() != before


_NO_WRITABLE_CACHE = """
import sys
import numba.core.caching as caching

def deny(self):  # what every locator meets when its folder is read-only (package, NUMBA_CACHE_DIR and HOME)
    raise PermissionError(13, "Permission denied", self.get_cache_path())

caching._CacheLocator.ensure_cache_path = deny
from dicetrace.cli import main
sys.argv = ["dicetrace", "simulate", "--slice", "seed", "--at", "1.65,3.9"]
main()
"""


@pytest.mark.slow
def test_no_writable_cache_folder_runs_without_the_disk_cache_and_says_so_in_one_line():
    """numba refuses ``cache=True`` with 'no locator available' when no folder can hold its cache: the
    command still runs (compiled, not cached), with one line on standard error, never an internal error."""
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-c", _NO_WRITABLE_CACHE], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "without the disk cache" in lines[0] and "NUMBA_CACHE_DIR" in lines[0]
    row = run.stdout.splitlines()[1].split()
    assert row[9:13] == ["3", "540", "0.54", "settled"]  # the red-sea throw, as with a cache
