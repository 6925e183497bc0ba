"""Every patch of a third-party library's internals that dicetrace makes, in one place.

Each patch names the versions it was written for and has a self-test
(:func:`self_test`, run by ``tests/core/test_compat.py``) that fails loudly,
naming the patch, when an upgrade moves what it relies on:

``install_cache_locator``  (numba 0.68)
    numba's on-disk cache keys a cached function on its own source file
    only; dicetrace's kernels are cached under a digest of all of
    ``core/**`` instead (``core._jit``).  Two cache locators are put first
    in numba's ``CacheImpl._locator_classes``: one for the user's cache
    folder, one for ``__pycache__`` beside the sources where that cannot be
    written.  Where numba's internals moved, nothing is installed (numba's
    default locators then cache per source file) and the self-test fails.
``nvvm_without_fma``  (numba-cuda 0.30.4)
    NVVM contracts a·b + c into fused multiply-adds by default, and
    numba-cuda has no public switch for its ``-fma=0`` option: inside this
    context ``nvvm.compile_ir`` is wrapped to add it, for the kernels
    compiled there (``core.gpu``).
``ensure_row_stack``  (numba-cuda 0.30.4 with numpy 2.5)
    numpy 2.5 removed ``np.row_stack``, which numba-cuda 0.30.4 still names
    at import: an alias to ``np.vstack`` (its documented replacement) before
    numba-cuda is imported.
``simulator_local_records``  (numba-cuda 0.30.4's simulator)
    The simulator makes ``cuda.local.array(shape, dtype)`` with ``np.empty``;
    for a record dtype its elements are ``np.void``, which has no attribute
    access to its fields, where the device's records have: the kernels read
    ``st.X``.  The simulator's local arrays of records are made
    ``np.recarray`` (whose elements, ``np.record``, have it).
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np

#: The versions each patch was written for and tested with.
NUMBA_TESTED = "0.68.1"
NUMBA_CUDA_TESTED = "0.30.4"


# ---------------------------------------------------------------- numba's cache locators


def install_cache_locator(core_dir: Path, digest: str, root: Path) -> bool:
    """Cache the numba functions defined under ``core_dir`` in ``root/<digest[:20]>``, stamped by ``digest``.

    Returns whether the locators are installed (False where numba's
    internals moved: numba's default locators then apply).  Where ``root``
    cannot be written, the second locator caches in ``__pycache__`` beside
    the sources, keyed by the digest and the files' times.
    """
    try:
        from numba.core import caching

        in_tree = caching.InTreeCacheLocator
        mixin = caching._SourceFileBackedLocatorMixin
        abstract = caching._CacheLocator
        impl = caching.CacheImpl
        impl._locator_classes  # noqa: B018 (the list the locators go into)
    except (ImportError, AttributeError):
        return False
    key = digest[:20]

    def in_core(py_file) -> bool:
        try:
            return Path(py_file).resolve().is_relative_to(core_dir)
        except OSError:
            return False

    class _CoreCacheLocator(mixin, abstract):
        """Kernels of ``dicetrace.core`` in ``cache_root()/<digest>``, stamped by the digest alone."""

        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            rel = Path(py_file).resolve().parent.relative_to(core_dir)
            self._cache_path = str(root / key / rel)

        def get_cache_path(self):
            return self._cache_path

        def get_source_stamp(self):
            return digest

        @classmethod
        def from_function(cls, py_func, py_file):
            if not in_core(py_file):
                return None
            self = cls(py_func, py_file)
            try:
                self.ensure_cache_path()
            except OSError:
                return None
            return self

    class _CoreInTreeCacheLocator(in_tree):
        """Where the user cache folder cannot be written: ``__pycache__`` beside the sources, digest and times."""

        @classmethod
        def from_function(cls, py_func, py_file):
            return super().from_function(py_func, py_file) if in_core(py_file) else None

        def get_source_stamp(self):
            return (super().get_source_stamp(), digest)

    if not any(c.__name__ == "_CoreCacheLocator" for c in impl._locator_classes):
        impl._locator_classes[0:0] = [_CoreCacheLocator, _CoreInTreeCacheLocator]
    return True


def cache_locator_installed() -> bool:
    """Whether :func:`install_cache_locator`'s locators are first in numba's list."""
    from numba.core import caching

    names = [c.__name__ for c in caching.CacheImpl._locator_classes[:2]]
    return names == ["_CoreCacheLocator", "_CoreInTreeCacheLocator"]


# ---------------------------------------------------------------- numpy 2.5 and numba-cuda


def ensure_row_stack() -> None:
    """``np.row_stack`` as an alias of ``np.vstack`` where numpy removed it (2.5), for numba-cuda 0.30.4's import."""
    if not hasattr(np, "row_stack"):
        np.row_stack = np.vstack


def simulator_local_records() -> None:
    """Local arrays of records in numba-cuda's simulator are ``np.recarray`` (attribute access to fields, as on the
    device); idempotent."""
    from numba.cuda.simulator import kernelapi

    local = kernelapi.FakeCUDALocal
    original = local.array
    if getattr(original, "_dicetrace_records", False):
        return

    def array(self, shape, dtype, alignment=None):
        a = original(self, shape, dtype, alignment)
        return a.view(np.recarray) if a.dtype.names else a

    array._dicetrace_records = True
    local.array = array


# ---------------------------------------------------------------- NVVM's -fma=0


@contextlib.contextmanager
def nvvm_without_fma(nvvm):
    """NVVM compiles with ``-fma=0`` inside: no contraction of a·b + c (``nvvm``: ``numba.cuda.cudadrv.nvvm``).

    numba-cuda passes its code library's options to ``nvvm.compile_ir``
    when it makes PTX; the option is added there for the kernels compiled
    in this context.  The caller holds a lock while inside (the swap is
    module-wide).
    """
    compile_ir = nvvm.compile_ir

    def strict(llvmir, **options):
        options["fma"] = False
        return compile_ir(llvmir, **options)

    nvvm.compile_ir = strict
    try:
        yield
    finally:
        nvvm.compile_ir = compile_ir


# ---------------------------------------------------------------- self-test


def self_test(*, cache_on: bool = False, cuda: bool = False) -> list[str]:
    """What no longer holds of the patches' premises, one line each (empty: all hold).

    Checks that numba's cache internals exist and, with ``cache_on`` (the
    kernel cache is on: ``_jit.CACHE``), that the locators are installed;
    with ``cuda``, that numba-cuda imports
    (after :func:`ensure_row_stack`) and that ``nvvm.compile_ir`` takes the
    options the ``-fma=0`` patch passes.
    """
    import inspect

    problems = []
    try:
        from numba.core import caching

        for name in ("InTreeCacheLocator", "_SourceFileBackedLocatorMixin", "_CacheLocator", "CacheImpl"):
            if not hasattr(caching, name):
                problems.append(f"install_cache_locator: numba.core.caching.{name} is gone (written for numba {NUMBA_TESTED})")
        if not isinstance(getattr(caching.CacheImpl, "_locator_classes", None), list):
            problems.append(f"install_cache_locator: numba's CacheImpl._locator_classes is no list (written for numba {NUMBA_TESTED})")
    except ImportError as exc:
        problems.append(f"install_cache_locator: numba.core.caching does not import ({exc})")
    if cache_on and not problems and not cache_locator_installed():
        problems.append("install_cache_locator: the kernel cache is on but dicetrace's locators are not first in numba's list")
    if cuda:
        ensure_row_stack()
        try:
            from numba.cuda.cudadrv import nvvm
        except ImportError as exc:
            problems.append(f"nvvm_without_fma: numba-cuda does not import ({exc}; written for {NUMBA_CUDA_TESTED})")
        else:
            params = inspect.signature(nvvm.compile_ir).parameters
            if not any(p.kind is p.VAR_KEYWORD for p in params.values()):
                problems.append(f"nvvm_without_fma: nvvm.compile_ir takes no **options any more (written for numba-cuda {NUMBA_CUDA_TESTED})")
            if os.environ.get("NUMBA_ENABLE_CUDASIM", "0") in ("", "0"):
                opts = getattr(nvvm, "CompilationUnit", None)
                if opts is None:
                    problems.append(f"nvvm_without_fma: nvvm.CompilationUnit is gone (written for numba-cuda {NUMBA_CUDA_TESTED})")
        try:
            from numba.cuda.simulator import kernelapi

            inspect.signature(kernelapi.FakeCUDALocal.array).bind(None, 1, np.float64)
        except (ImportError, AttributeError, TypeError) as exc:
            problems.append(f"simulator_local_records: the simulator's FakeCUDALocal.array moved ({exc}; written for "
                            f"numba-cuda {NUMBA_CUDA_TESTED})")
    return problems
