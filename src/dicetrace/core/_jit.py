"""The one jit decorator, the on-disk cache and compile-time specialisation.

Every compiler option of dicetrace lives here.  ``DICETRACE_CACHE=0`` turns
numba's on-disk cache off (it is on by default: a new process then loads
compiled kernels in ~0.05 s instead of compiling).  No fast-math flag
anywhere: every kernel compiles with strict IEEE arithmetic, with no
contraction into fused multiply-adds and no re-association.  The `seed`
preset must reproduce the 2019 program bit for bit (docs/model.md §5.5);
and a kernel's results must not depend on how it was compiled.  With
LLVM's ``contract`` flag they did: where a fused multiply-add falls
depends on which callees the compiler inlines, and a contact scheme's
kernel compiled in the running process and the same kernel loaded from
the disk cache rounded differently (docs/model.md §9).

numba's cache checks only the source file of the cached function, so a
kernel in ``loop.py`` would keep running old code after ``fast.py`` or
``model.py`` changed.  The kernels of ``dicetrace.core`` (subpackages
included) are therefore cached under a digest of all of ``core/**/*.py``
but ``gpu.py`` (which compiles them for a GPU and holds no CPU kernel)
and of the constants of the bottom layers that kernels compile in (the
integrator table, the status codes, the mode constants and the field order
of ``KernelParams``): any change there recompiles them.  The digest is the
whole key, so the cache lives in the user's cache folder
(:func:`cache_root`: ``DICETRACE_CACHE_DIR``, else ``$NUMBA_CACHE_DIR/dicetrace``,
else ``$XDG_CACHE_HOME`` or ``~/.cache``, then ``dicetrace/kernels/<digest>``)
and every checkout, clone or install of the same kernel sources shares it:
a fresh clone of an unchanged release compiles nothing.  The six most
recently used digests are kept, older ones removed.  Where that folder
cannot be written, the cache falls back to ``__pycache__`` beside the
sources (keyed by the digest and the files' times), and where nothing can
be written, kernels compile without a disk cache (one line says so).

The cache locators are a patch of numba's internals: ``_compat`` holds it,
with the versions it was written for and its self-test.

Compile-time variants of one source (a run loop per scheme, a sub-step per
Runge–Kutta tableau, the contact driver per sub-step method) are closures
made by a factory (``loop.make_roll``, ``contact_driver.make_drive``,
``erk.erk_substep``): numba compiles closure values in as constants.  They
close over modules, booleans, numbers and arrays only, which numba's cache
keys on by value (a module by its name: numba pickles the closure's values
to key the cache, and a module in ``sys.modules`` pickles as its name).  A
compiled function in a closure would be keyed by an identity that changes
from one process to the next, and the cache would never hit: where one
kernel calls another that a factory made (the batch kernel calls a run
loop), it calls it through a module that holds it (``kernels.kernels_of``).

Inlining.  What a run loop calls at every stage (the force law, the
sub-step, the rotation) is ``jit(inline="always")``: numba copies it into
each caller at its intermediate representation, so LLVM sees one function
and nothing is paid per call.  Each copy is typed and lowered again, which is
most of a loop's compile time.  The branches the uniform cube never takes
(``inertia.body_omega``, ``erk.body_stage_omega``, ``model.face_below``: ω and
the face of a box or a loaded die) are plain ``jit`` functions, compiled once
and called: that took a sixth off the compile of ``contact-tsit5``'s summary
loop (94.6 → 79.0 s of CPU on a cold cache, measured one after the other), and
the cube's throws cost what they did within the timing's noise (``physical``
1.013, ``seed`` 1.027 of before, overlapping ranges).  Moving a
function the cube does run out of line is not free: ``contact_forces`` out of
line made ``physical`` 4 % and ``seed`` 11 % slower a throw, and the dense
output and free-flight helpers 6 % (``benchmarks/bench_revisions.py``).

On the GPU (``core.gpu``) numba-cuda compiles the same functions as device
functions and NVVM inlines every one of them into the kernel, the plain
``jit`` ones too: out of line on the CPU is not out of line there.  What
decides a GPU kernel's registers is what NVVM keeps in them.  A thread's
records are local arrays, which NVVM knows nothing else can touch, so it
kept every value it had read from them or written to them for as long as
it was used again: the Runge–Kutta stages (13 numbers a stage, read back by
every later stage, the solution and the error estimate) across the force
evaluations of a sub-step, ~80 doubles on top of the driver's own, and the
general kernel of ``contact-tsit5`` spilled 1.6 kB a thread
(``benchmarks/bench_ptxas.py``).  :func:`gpu_fence` marks where a device
function reads its records again instead: after each stage of a
Runge–Kutta sub-step, at its end and between DOP853's two error estimates
(``methods.erk``), and at the start of each sub-step of the contact
driver; the kernels hand their local records to it (``core.gpu._fenced``).
With them the contact kernels of ``physical`` keep to 255 registers without
spilling (docs/gpu.md).  A fence is nothing on the CPU (its code is
empty: a function compiles to the same instructions with or without it,
``tests/core/test_gpu_fence.py``).
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import sys
from pathlib import Path

import numba
from llvmlite import ir as llvm_ir
from numba.core import config as numba_config
from numba.core import types as numba_types
from numba.extending import intrinsic

from dicetrace.core import _compat

CACHE = os.environ.get("DICETRACE_CACHE", "1") not in ("0", "false", "no")

_CORE_DIR = Path(__file__).resolve().parent


def _baked_constants() -> bytes:
    """The bottom-layer values that kernels compile in as constants."""
    from dicetrace import params
    from dicetrace.integrators import INTEGRATORS
    from dicetrace.status import Status

    rows = [(s.name, s.kernel_id, s.scheme) for s in INTEGRATORS.values()]
    statuses = [(s.name, int(s)) for s in Status]
    modes = [
        params.FRICTION_SPECTRAL,
        params.FRICTION_PER_NODE,
        params.ENERGY_POINT_MASS,
        params.ENERGY_RIGID,
        params.NODE_SIGNS.tobytes().hex(),
        params.KernelParams._fields,
        params.TOL_LOOSEST,
    ]
    return repr((rows, statuses, modes)).encode()


#: Modules of ``core`` that hold no CPU kernel: a change there recompiles nothing on the CPU (``gpu.py``'s own
#: kernels are keyed by numba-cuda on that file and, through their closure, on this digest).
_NOT_KERNELS = frozenset({"gpu.py"})


def _core_digest() -> str:
    h = hashlib.sha256()
    for path in sorted(p for p in _CORE_DIR.rglob("*.py") if p.relative_to(_CORE_DIR).as_posix() not in _NOT_KERNELS):
        h.update(path.relative_to(_CORE_DIR).as_posix().encode())
        h.update(path.read_bytes())
    h.update(_baked_constants())
    return h.hexdigest()


@functools.cache
def kernel_digest() -> str:
    """The digest that stamps the cached kernels (``core/**/*.py`` but gpu.py, and the baked constants), once per process.

    What a cache of simulation *results* keys on too: when it changes, the
    kernels may compute something else.
    """
    return _core_digest()


#: How many kernel digests :func:`cache_root` keeps (the most recently used; older ones are removed).
KEEP_DIGESTS = 6


def cache_root() -> Path:
    """The folder under which compiled kernels are kept, one sub-folder per kernel digest."""
    if os.environ.get("DICETRACE_CACHE_DIR"):
        return Path(os.environ["DICETRACE_CACHE_DIR"])
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"]) / "dicetrace"
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "dicetrace" / "kernels"


def prune_digests(root: Path, current: str, keep: int = KEEP_DIGESTS) -> list[Path]:
    """Remove the digest folders under ``root`` beyond the ``keep`` most recently used (never ``current``); return them.

    Best effort: a folder another process is using is only recompiled there
    if it goes; nothing fails here.
    """
    try:
        folders = [p for p in root.iterdir() if p.is_dir() and p.name != current]
        folders.sort(key=lambda p: p.stat().st_mtime, reverse=True)
    except OSError:
        return []
    gone = folders[max(0, keep - 1):]
    for p in gone:
        shutil.rmtree(p, ignore_errors=True)
    return gone


def _install_core_locator() -> None:
    """Cache the kernels of ``dicetrace.core`` under the kernel digest (``_compat.install_cache_locator``)."""
    digest = kernel_digest()
    root = cache_root()
    if not _compat.install_cache_locator(_CORE_DIR, digest, root):
        return  # numba's internals moved: its default locators cache per source file (the self-test says so)
    key = digest[:20]
    try:
        (root / key).mkdir(parents=True, exist_ok=True)
        os.utime(root / key)  # the most recently used digest
    except OSError:
        return
    prune_digests(root, key)


if CACHE:
    _install_core_locator()

_OPTIONS = dict(cache=CACHE, fastmath=False, error_model="numpy", nogil=True)


def _without_disk_cache(why: str) -> None:
    """Compile without numba's on-disk cache from now on, and say so once on standard error."""
    global CACHE
    if CACHE:
        CACHE = False
        _OPTIONS["cache"] = False
        sys.stderr.write(
            f"dicetrace: no writable folder for numba's kernel cache ({why}); compiling without the disk cache"
            " (set DICETRACE_CACHE_DIR to a writable folder to keep compiled kernels)\n"
        )


def _njit(fn, opts: dict):
    """``numba.njit(**opts)(fn)``; where no folder can hold the cache, without it (numba refuses with 'no locator available')."""
    if opts.get("cache") and not CACHE:  # the cache was turned off after ``opts`` was made
        opts = {**opts, "cache": False}
    try:
        return numba.njit(**opts)(fn)
    except RuntimeError as exc:
        if not opts.get("cache") or "no locator available" not in str(exc):
            raise
    _without_disk_cache("every folder numba tries is read-only")
    return numba.njit(**{**opts, "cache": False})(fn)


def jit(fn=None, **extra):
    """``numba.njit`` with dicetrace's options (cache, no fast-math)."""
    opts = {**_OPTIONS, **extra}
    if fn is None:
        return lambda f: _njit(f, opts)
    return _njit(fn, opts)


def jit_parallel(fn):
    """``jit`` with ``parallel=True`` for ``prange`` batch kernels."""
    return _njit(fn, {**_OPTIONS, "parallel": True})


@intrinsic
def _memory_fence(typingctx):
    """An empty inline assembly statement that clobbers memory, on a GPU only (no code on the CPU)."""

    def codegen(context, builder, signature, args):
        if builder.module.triple.startswith("nvptx"):  # numba-cuda compiling a device function
            asm = llvm_ir.InlineAsm(llvm_ir.FunctionType(llvm_ir.VoidType(), []), "", "~{memory}", side_effect=True)
            builder.call(asm, [])
        return context.get_dummy_value()

    return numba_types.void(), codegen


def _no_fence():
    """:func:`gpu_fence` run as plain Python (``NUMBA_DISABLE_JIT``, numba-cuda's simulator): nothing."""


#: ``gpu_fence()``, in a kernel: on the GPU, values read from memory before this point are read again after it
#: (NVVM may not keep them in registers across it: a compiler barrier, an empty ``asm volatile`` that clobbers
#: memory); nothing on the CPU, where it compiles to no instruction.  The GPU's kernels make their local records
#: visible to it (``core.gpu``); see "Inlining" above for where it stands and why.
gpu_fence = _no_fence if numba_config.DISABLE_JIT else _memory_fence
