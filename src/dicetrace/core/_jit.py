"""The one jit decorator: every compiler option of dicetrace lives here.

``DICETRACE_CACHE=0`` turns numba's on-disk cache off (it is on by default:
a new process then loads compiled kernels in ~0.05 s instead of compiling).
No fast-math: the `seed` preset must reproduce the 2019 program bit for bit,
so contraction into fused multiply-adds and re-association are not allowed.

numba's cache checks only the source file of the cached function, so a
kernel in ``loop.py`` would keep running old code after ``fast.py`` or
``model.py`` changed.  ``_CoreCacheLocator`` stamps every cached kernel of
``dicetrace.core`` with a digest of all of ``core/*.py`` instead, so any
change there recompiles them.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba

CACHE = os.environ.get("DICETRACE_CACHE", "1") not in ("0", "false", "no")

_CORE_DIR = Path(__file__).resolve().parent


def _core_digest() -> str:
    h = hashlib.sha256()
    for path in sorted(_CORE_DIR.glob("*.py")):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def _install_core_locator() -> None:
    try:
        from numba.core import caching

        base = caching.InTreeCacheLocator
        impl = caching.CacheImpl
    except (ImportError, AttributeError):  # numba internals moved: keep numba's default
        return
    digest = _core_digest()

    class _CoreCacheLocator(base):
        @classmethod
        def from_function(cls, py_func, py_file):
            try:
                if Path(py_file).resolve().parent != _CORE_DIR:
                    return None
            except OSError:
                return None
            return super().from_function(py_func, py_file)

        def get_source_stamp(self):
            return (super().get_source_stamp(), digest)

    if not any(c.__name__ == "_CoreCacheLocator" for c in impl._locator_classes):
        impl._locator_classes.insert(0, _CoreCacheLocator)


if CACHE:
    _install_core_locator()

_OPTIONS = dict(cache=CACHE, fastmath=False, error_model="numpy", nogil=True)


def jit(fn=None, **extra):
    """``numba.njit`` with dicetrace's options (cache, no fast-math)."""
    opts = {**_OPTIONS, **extra}
    if fn is None:
        return lambda f: numba.njit(**opts)(f)
    return numba.njit(**opts)(fn)


def jit_parallel(fn):
    """``jit`` with ``parallel=True`` for ``prange`` batch kernels."""
    return numba.njit(**_OPTIONS, parallel=True)(fn)
