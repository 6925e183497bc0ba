"""The patches of third-party internals (``core._compat``): each one's premises hold on the installed versions.

When an upgrade of numba, numba-cuda or numpy moves what a patch relies
on, :func:`_compat.self_test` names the patch and what moved, and these
tests fail with that line.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from dicetrace.core import _compat, _jit


def test_every_patch_premise_holds_on_the_installed_numba():
    assert _compat.self_test(cache_on=_jit.CACHE) == []


def test_the_kernel_cache_locators_are_first_in_numbas_list():
    if not _jit.CACHE:
        pytest.skip("DICETRACE_CACHE is off: no locator is installed")
    assert _compat.cache_locator_installed()


def test_a_kernel_of_core_is_cached_under_the_digest(tmp_path):
    """A core kernel's cache folder is the digest's, not numba's default beside the source."""
    if not _jit.CACHE:
        pytest.skip("DICETRACE_CACHE is off")
    from dicetrace.core.model import init_offsets

    impl = init_offsets._cache._impl
    assert type(impl.locator).__name__ in ("_CoreCacheLocator", "_CoreInTreeCacheLocator")
    if type(impl.locator).__name__ == "_CoreCacheLocator":
        assert _jit.kernel_digest()[:20] in impl.locator.get_cache_path()
        assert impl.locator.get_source_stamp() == _jit.kernel_digest()


def test_self_test_names_a_moved_locator_list(monkeypatch):
    """If numba's locator list stops being a list (its internals moved), the self-test says so by name."""
    from numba.core import caching

    monkeypatch.setattr(caching.CacheImpl, "_locator_classes", tuple(caching.CacheImpl._locator_classes))
    problems = _compat.self_test(cache_on=_jit.CACHE)
    assert any(p.startswith("install_cache_locator:") and "_locator_classes" in p for p in problems), problems


def test_install_refuses_quietly_where_numba_moved(monkeypatch, tmp_path):
    """Where numba's caching internals are missing, nothing is installed (numba's default locators stay)."""
    from numba.core import caching

    monkeypatch.delattr(caching, "_SourceFileBackedLocatorMixin")
    assert _compat.install_cache_locator(tmp_path, "0" * 64, tmp_path) is False


def test_row_stack_alias_is_vstack(monkeypatch):
    """``ensure_row_stack`` adds ``np.row_stack`` as ``np.vstack`` where numpy removed it, and keeps numpy's own."""
    own = getattr(np, "row_stack", None)
    if own is not None:
        monkeypatch.delattr(np, "row_stack")
    _compat.ensure_row_stack()
    assert np.row_stack is np.vstack
    a = np.array([1.0, 2.0])
    assert np.array_equal(np.row_stack((a, a)), np.array([[1.0, 2.0], [1.0, 2.0]]))


def test_nvvm_patch_adds_fma_off_and_restores():
    """Inside ``nvvm_without_fma`` every compile gets ``fma=False``; outside, the original is back."""

    class FakeNVVM:
        seen = []

        @staticmethod
        def compile_ir(llvmir, **options):
            FakeNVVM.seen.append(dict(options))
            return "ptx"

    original = FakeNVVM.compile_ir
    with _compat.nvvm_without_fma(FakeNVVM):
        assert FakeNVVM.compile_ir("ir", opt=3) == "ptx"
    assert FakeNVVM.seen == [{"opt": 3, "fma": False}]
    assert FakeNVVM.compile_ir is original


@pytest.mark.slow
def test_numba_cuda_patch_premises_hold():
    """With numba-cuda installed (the test extras), its patches' premises hold (in a fresh interpreter: numba-cuda
    is imported only where a GPU is asked for)."""
    pytest.importorskip("numba_cuda")
    code = textwrap.dedent(
        """
        from dicetrace.core import _compat, _jit
        print("\\n".join(_compat.self_test(cache_on=_jit.CACHE, cuda=True)) or "OK")
        """
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip() == "OK", res.stdout
