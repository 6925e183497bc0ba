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
