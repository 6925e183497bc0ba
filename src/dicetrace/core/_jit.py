"""The one jit decorator: every compiler option of dicetrace lives here.

``DICETRACE_CACHE=0`` turns numba's on-disk cache off (it is on by default:
a new process then loads compiled kernels in ~0.05 s instead of compiling).
No fast-math: the `seed` preset must reproduce the 2019 program bit for bit,
so contraction into fused multiply-adds and re-association are not allowed.
"""

from __future__ import annotations

import os

import numba

CACHE = os.environ.get("DICETRACE_CACHE", "1") not in ("0", "false", "no")

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
