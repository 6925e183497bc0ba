"""The GPU backend: the CPU's kernels, compiled by numba-cuda for an NVIDIA GPU, one thread per throw.

There is no second copy of the physics here.  numba-cuda compiles a
function that numba's CPU ``jit`` made (``core._jit``) as a device function
when device code calls it, so the force law, the steps, the sub-step
drivers and the run loop are the very functions the CPU runs.  This module
only adds the two kernels that give each thread its throw:

``seed kernel``
    the `seed` preset's specialised summary kernel
    (``fast.roll_summary_sie_in``) in per-thread local arrays, wherever it
    applies on the CPU (``fast.applies``);
``general kernel``
    a scheme's summary run loop (``scheme.roll_summary``, ``loop.make_roll``),
    in a per-thread state record in device memory.

Both are cached on disk by numba-cuda (beside this file, or in the user's
cache where that cannot be written), keyed on the kernel digest of
``core/**`` as the CPU's kernels are: a first run compiles them (tens of
seconds for a contact scheme), later ones load them.

Arithmetic.  The seed path's kernels are compiled as on the CPU, without
contraction into fused multiply-adds (NVVM contracts by default; its
``-fma=0`` option is set for those kernels): only libdevice's sin, cos, exp
and sqrt can then differ from the host's, in the last ulp.  The contact
schemes, which the CPU compiles with contraction (``_jit.jit_fused``), are
compiled with NVVM's default contraction: the same model, rounded
differently, so their throws agree with the CPU's to rounding and, through
the chaos, in outcome wherever a throw is not within rounding of a border.

Memory.  Each thread owns ``cap`` contact sets in device memory and, on
the general kernel, one state record (``core.state.STATE``, 3.8 kB).
``run_batch_cuda`` runs one chunk; ``dicetrace.batch_chunks`` sizes chunks
to the device's free memory and retries the throws that fill their buffer,
as on the CPU.

numba-cuda is optional (``pip install 'dicetrace[cuda]'``) and this module
imports it: import this module only where a GPU is asked for
(``dicetrace.devices`` says whether one can be used).  Under numba-cuda's
simulator (``NUMBA_ENABLE_CUDASIM=1``) the kernels run on the CPU, in
Python, calling the CPU's compiled functions.
"""

from __future__ import annotations

import contextlib
import os
import threading

import numpy as np

if not hasattr(np, "row_stack"):  # numpy 2.5 removed it; numba-cuda 0.30 still names it
    np.row_stack = np.vstack

from numba import cuda, float64, typeof  # noqa: E402 (after the alias above)
from numba.cuda.cudadrv import nvvm  # noqa: E402

from dicetrace.core import fast, loop  # noqa: E402
from dicetrace.core._jit import CACHE, kernel_digest  # noqa: E402
from dicetrace.core.kernels import scheme_of  # noqa: E402
from dicetrace.core.state import new_states  # noqa: E402

#: Threads per block: the kernels hold ~180 registers a thread, so blocks of 128 keep several resident.
THREADS_PER_BLOCK = 128


def simulated() -> bool:
    """Whether numba-cuda's simulator stands in for a GPU (``NUMBA_ENABLE_CUDASIM=1``)."""
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


def device_count() -> int:
    """How many CUDA devices this process sees (1 under the simulator)."""
    return 1 if simulated() else len(cuda.gpus)


def select_device(k: int) -> None:
    """Make device ``k`` this thread's current device (nothing under the simulator)."""
    if not simulated():
        cuda.select_device(k)


def device_name() -> str:
    """The device the kernels run on, in words (e.g. 'NVIDIA H200', or the simulator)."""
    if simulated():
        return "numba-cuda simulator"
    dev = cuda.get_current_device()
    name = dev.name.decode() if isinstance(dev.name, bytes) else str(dev.name)
    return name


def free_memory() -> int:
    """Free device memory in bytes (the simulator: 2 GiB, a size for tests)."""
    if simulated():
        return 2 << 30
    free, _total = cuda.current_context().get_memory_info()
    return int(free)


@contextlib.contextmanager
def _nvvm_without_fma():
    """NVVM compiles with ``-fma=0`` inside: no contraction of a·b + c, as the CPU compiles the seed path.

    numba-cuda passes its code library's options to ``nvvm.compile_ir``
    when it makes PTX; it has no public switch for this one, so the option
    is added there for the kernels compiled in this context.
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


def _make_seed_kernel(tag: int):
    """The one-thread-per-throw kernel around the seed path's summary kernel (``fast.roll_summary_sie_in``).

    ``tag``: 60 bits of the kernel digest (``_jit.kernel_digest``), closed
    over so that numba-cuda's disk cache, which keys a kernel on its own
    code and its closure, never loads a kernel compiled from other core
    sources.
    """

    def seed_kernel(ics, off0, kp, cap, status, steps, outcome, nsets, sets, set_steps):
        i = cuda.grid(1)
        if i < ics.shape[0] and tag >= 0:
            off = cuda.local.array((8, 3), float64)
            F = cuda.local.array((8, 3), float64)
            uk = cuda.local.array((8, 3), float64)
            z = cuda.local.array(8, float64)
            P = cuda.local.array(8, float64)
            lo = i * cap
            s, n, o, ns = fast.roll_summary_sie_in(ics[i], off0, kp, sets[lo : lo + cap], set_steps[lo : lo + cap],
                                                   off, F, uk, z, P)
            status[i] = s
            steps[i] = n
            outcome[i] = o
            nsets[i] = ns

    return seed_kernel


def _make_general_kernel(scheme, tag: int):
    """The one-thread-per-throw kernel around ``scheme.roll_summary`` (``loop.make_roll``); ``tag`` as above."""

    def general_kernel(ics, off0, kp, cap, states, status, steps, outcome, nsets, sets, set_steps, e0, e1, e2):
        i = cuda.grid(1)
        if i < ics.shape[0] and tag >= 0:
            lo = i * cap
            s, n, o, ns = scheme.roll_summary(ics[i], off0, kp, states[i : i + 1], sets[lo : lo + cap],
                                              set_steps[lo : lo + cap], e0, e1, e2)
            status[i] = s
            steps[i] = n
            outcome[i] = o
            nsets[i] = ns

    return general_kernel


def _fused(scheme) -> bool:
    """Whether the CPU compiles this scheme's step with contraction (``_jit.jit_fused``)."""
    return bool(getattr(scheme.step, "targetoptions", {}).get("fastmath"))


_KERNELS: dict = {}


def _kernel(integ: int, seed_path: bool):
    """The CUDA dispatcher for integrator ``integ`` (kernel id), the seed kernel or the general one, and whether strict."""
    scheme = scheme_of(integ)
    key = "seed" if seed_path else scheme.__name__
    if key not in _KERNELS:
        tag = int(kernel_digest()[:15], 16)
        if seed_path:
            fn, strict = _make_seed_kernel(tag), True
        else:
            fn, strict = _make_general_kernel(scheme, tag), not _fused(scheme)
        fn.__qualname__ = fn.__name__ = f"{fn.__name__}_{key.rsplit('.', 1)[-1]}"
        _KERNELS[key] = (cuda.jit(fn, cache=CACHE), strict)
    return _KERNELS[key]


#: Held while a strict kernel compiles: its ``-fma=0`` option is set module-wide (``_nvvm_without_fma``), and a
#: thread running another GPU must neither restore it too early nor compile under it.
_COMPILE_LOCK = threading.Lock()


def _launch(kernel, strict: bool, m: int, args) -> None:
    """Launch ``kernel`` over m threads; compile it first, with ``-fma=0`` where ``strict`` (or load it from the cache)."""
    blocks = (m + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
    sig = tuple(typeof(a) for a in args)
    if not simulated() and sig not in kernel.overloads:
        with _COMPILE_LOCK:
            if sig not in kernel.overloads:
                with _nvvm_without_fma() if strict else contextlib.nullcontext():
                    kernel.compile(sig)
    kernel[blocks, THREADS_PER_BLOCK](*args)


def uses_seed_kernel(kp, off0, integ: int) -> bool:
    """Whether throws of this configuration run the seed kernel (the CPU's specialised kernel applies)."""
    scheme = scheme_of(integ)
    return hasattr(scheme, "summary") and scheme.summary is fast.roll_summary_sie and bool(fast.applies(kp, off0))


def bytes_per_throw(integ: int, cap: int, kp=None, off0=None) -> int:
    """Device memory one throw of a chunk takes: IC, summaries, ``cap`` contact sets and (general kernel) its state."""
    state = 0 if (kp is not None and uses_seed_kernel(kp, off0, integ)) else new_states(1).itemsize
    return 6 * 8 + 1 + 8 + 1 + 8 + 5 * cap + state


def run_batch_cuda(ics, off0, kp, integ, cap, status, steps, outcome, nsets, sets, set_steps) -> None:
    """``core.kernels.run_batch`` on the GPU: the same arguments, the outputs written in place.

    One chunk: the caller sizes it to the device's memory
    (:func:`bytes_per_throw`, :func:`free_memory`).  Threads may run chunks
    on several GPUs at once; under the simulator, which swaps this module's
    ``cuda`` for a stand-in while a kernel runs, one at a time.
    """
    with _SIMULATOR_LOCK if simulated() else contextlib.nullcontext():
        _run_batch_cuda(ics, off0, kp, integ, cap, status, steps, outcome, nsets, sets, set_steps)


_SIMULATOR_LOCK = threading.Lock()


def _run_batch_cuda(ics, off0, kp, integ, cap, status, steps, outcome, nsets, sets, set_steps) -> None:
    m = len(ics)
    if m == 0:
        return
    seed_path = uses_seed_kernel(kp, off0, integ)
    kernel, strict = _kernel(integ, seed_path)
    d_ics = cuda.to_device(np.ascontiguousarray(ics, dtype=np.float64))
    d_off0 = cuda.to_device(np.ascontiguousarray(off0, dtype=np.float64))
    outs = [cuda.device_array(a.shape, a.dtype) for a in (status, steps, outcome, nsets, sets, set_steps)]
    if seed_path:
        args = (d_ics, d_off0, kp, cap, *outs)
    else:
        states = cuda.to_device(new_states(m))
        empty = (cuda.device_array((0, loop.STATE_COLS)), cuda.device_array((0, loop.FORCE_COLS)),
                 cuda.device_array((0, loop.ENERGY_COLS)))
        args = (d_ics, d_off0, kp, cap, states, *outs, *empty)
    _launch(kernel, strict, m, args)
    for host, dev in zip((status, steps, outcome, nsets, sets, set_steps), outs):
        dev.copy_to_host(host)
