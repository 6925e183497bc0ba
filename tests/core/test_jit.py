"""The on-disk kernel cache is keyed by what kernels compile in (``core._jit``)."""

from __future__ import annotations

import ast
import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

import dicetrace
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
@pytest.mark.long
def test_no_writable_cache_folder_runs_without_the_disk_cache_and_says_so_in_one_line():
    """numba refuses ``cache=True`` with 'no locator available' when no folder can hold its cache: the
    command still runs (compiled, not cached), with one line on standard error, never an internal error."""
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-c", _NO_WRITABLE_CACHE], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "without the disk cache" in lines[0] and "DICETRACE_CACHE_DIR" in lines[0]
    row = run.stdout.splitlines()[1].split()
    assert row[9:13] == ["3", "540", "0.54", "settled"]  # the red-sea throw, as with a cache


_COMPILES = """
import sys
from numba.core import event

compiled = []

class Count(event.Listener):
    def on_start(self, ev):
        compiled.append(1)

    def on_end(self, ev):
        pass

event.register("numba:compile", Count())
from dicetrace.core import _jit
from dicetrace.core.rotation import norm3

print(norm3(3.0, 4.0, 12.0), len(compiled), _jit.kernel_digest()[:20])
"""


def _checkout(tmp_path, name):
    """A copy of the package's sources, as a second clone of the same release would have them (new paths, new times)."""
    src = tmp_path / name / "src"
    shutil.copytree(Path(dicetrace.__file__).resolve().parent, src / "dicetrace",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"), copy_function=shutil.copy)
    return src


def _run(src, cache):
    import subprocess
    import sys

    env = dict(os.environ, PYTHONPATH=str(src), DICETRACE_CACHE_DIR=str(cache))
    env.pop("DICETRACE_CACHE", None)
    out = subprocess.run([sys.executable, "-c", _COMPILES], capture_output=True, text=True, env=env, timeout=300,
                         cwd=src)
    assert out.returncode == 0, out.stderr
    value, compiles, digest = out.stdout.split()
    return float(value), int(compiles), digest


@pytest.mark.long
def test_two_checkouts_of_the_same_kernel_sources_share_their_compiled_kernels(tmp_path):
    """The kernel cache is keyed by the digest of the kernel sources, not by their paths or file times: a
    second clone of the same code loads what the first compiled; a changed kernel source compiles anew."""
    cache = tmp_path / "cache"
    a = _checkout(tmp_path, "a")
    time.sleep(0.01)  # file times as a later clone's (copy_function=shutil.copy keeps no times)
    b = _checkout(tmp_path, "b")
    first = _run(a, cache)
    assert first[0] == 13.0 and first[1] > 0  # compiled, into the shared folder
    assert (cache / first[2]).is_dir() and any((cache / first[2]).rglob("*.nbi"))
    second = _run(b, cache)
    assert second == (13.0, 0, first[2])  # loaded: nothing compiled
    with open(b / "dicetrace" / "core" / "rotation.py", "a") as f:
        f.write("\n# a change to a kernel source\n")
    third = _run(b, cache)
    assert third[0] == 13.0 and third[1] > 0 and third[2] != first[2]
    assert sorted(p.name for p in cache.iterdir()) == sorted([first[2], third[2]])


def test_only_the_most_recently_used_digests_are_kept(tmp_path):
    for i in range(9):
        d = tmp_path / f"digest{i}"
        d.mkdir()
        os.utime(d, (1_000_000 + i, 1_000_000 + i))
    gone = _jit.prune_digests(tmp_path, "digest0", keep=4)
    assert sorted(p.name for p in gone) == [f"digest{i}" for i in range(1, 6)]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["digest0", "digest6", "digest7", "digest8"]


def test_every_kernel_compiles_with_strict_arithmetic():
    """No kernel of ``dicetrace.core`` carries a fast-math flag (``contract`` fused multiply-adds, ``arcp``
    reciprocals, ...): where the compiler places them depends on what it inlines, and contact-scheme kernels
    that had them rounded differently freshly compiled and loaded from the disk cache (docs/model.md §9)."""
    import importlib
    import pkgutil

    from numba.core.dispatcher import Dispatcher

    seen = 0
    for info in pkgutil.walk_packages(dicetrace.core.__path__, "dicetrace.core."):
        if info.name == "dicetrace.core.gpu":  # imports numba-cuda; its kernels are compiled with -fma=0 (test_gpu)
            continue
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if isinstance(value, Dispatcher):
                assert not value.targetoptions.get("fastmath"), f"{info.name}.{name}: {value.targetoptions}"
                seen += 1
    assert seen > 100
