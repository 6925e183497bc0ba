"""The GPU backend: the CPU's kernels, compiled by numba-cuda for an NVIDIA GPU, one thread per throw.

There is no second copy of the physics here.  numba-cuda compiles a
function that numba's CPU ``jit`` made (``core._jit``) as a device function
when device code calls it, so the force law, the steps, the sub-step
drivers and the run loop are the very functions the CPU runs.  This module
only adds the kernels that give each thread its throw (and one that packs
the contact sets, their steps and the events' times the throws used, for
the copy back):

``seed kernel``
    the `seed` preset's specialised summary kernel
    (``fast.roll_summary_sie_in``) in per-thread local arrays, wherever it
    applies on the CPU (``fast.applies``);
``general kernel``
    a scheme's summary run loop (``roll_summary``, ``loop.make_roll``), its
    motion and work records (``core.state``: what its scheme uses) in the
    thread's local memory, which the hardware interleaves across a warp;
``events kernel``
    a contact scheme's events loop (``roll_events``: exact contact events,
    docs/model.md §8.1), likewise, with each thread's event times beside
    its sets;
``held kernels``
    the general and events kernels with each throw's records in device
    memory, for the throws that outlive a slice of ``kernels.SLICE_STEPS``
    steps (their records must outlive a launch; only with a time cap above
    65 s of 1 ms steps): launch after launch goes on with them, and Python
    runs between launches (Ctrl-C stops them).

All are cached on disk by numba-cuda (beside this file, or in the user's
cache where that cannot be written), keyed on the kernel digest of
``core/**`` as the CPU's kernels are: a first run compiles them (tens of
seconds for a contact scheme), later ones load them.

Arithmetic.  Every kernel is compiled as on the CPU, without contraction
into fused multiply-adds (NVVM contracts by default; its ``-fma=0`` option
is set for every kernel here): the arithmetic is the CPU's, operation for
operation, and only libdevice's sin, cos and exp can differ from the
host's, in the last ulp (sqrt is correctly rounded on both).

Memory and transfers.  Each thread owns ``cap`` contact sets in device
memory; its records are local.  ``run_batch_cuda`` runs one chunk on the calling host
thread's own CUDA stream, with that thread's pinned host buffers and device
buffers (grown as needed, kept for its next chunk): the ICs go in, the
kernel runs, the summaries come back, and then only the contact sets the
throws used (a gather kernel packs them end to end on the device).
``dicetrace.batch_chunks`` runs :func:`streams_per_device` host threads per
GPU, so that one chunk's transfers and host work overlap another's compute;
it sizes chunks to the device's free memory and retries the throws that
fill their buffer, as on the CPU.

What to keep.  :func:`run_batch_cuda` takes the request a CPU batch takes (a
:class:`~dicetrace.saving.Record` asking for events, or None) and the request
stops at the host: a kernel's arguments are what numba-cuda can type and
copy (arrays, scalars, records and tuples of them, as ``kp``), never a Python
object.  From the request the host chooses the kernel (its compile-time
``events`` flag, :func:`_kernel`) and makes the outputs on the device with one
function, :func:`_device_out`, as the named
:class:`~dicetrace.core.loop.BatchOut` the CPU's batch writes.  The kernels'
parameters are still positional (their bodies, and the signatures cached on
disk, are not changed here), so the host passes that structure's fields in
order, with what the loop kernels take for outputs and records a launch does
not use: event times of length 0, trace arrays of no rows, and (but in the
held kernels) motion and work records of no rows.  Inside, each thread
builds its run loop's :class:`~dicetrace.core.loop.RollOut` from them, as the
CPU's batch does.  (numba-cuda flattens a tuple argument into its fields, so
a kernel could take the ``BatchOut`` whole: a change of the kernels' bodies.)

numba-cuda is optional (``pip install 'dicetrace[cuda]'``) and this module
imports it: import this module only where a GPU is asked for
(``dicetrace.devices`` says whether one can be used).  Under numba-cuda's
simulator (``NUMBA_ENABLE_CUDASIM=1``) the kernels run on the CPU, in
Python, calling the CPU's compiled functions.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import threading

import numpy as np

from dicetrace.core import _compat

_compat.ensure_row_stack()  # numpy 2.5 removed np.row_stack; numba-cuda 0.30.4 still names it

from numba import cuda, float64, typeof  # noqa: E402 (after the alias above)
from numba.cuda.cudadrv import nvvm  # noqa: E402

from dicetrace.core import fast, loop  # noqa: E402
from dicetrace.core._jit import CACHE, kernel_digest  # noqa: E402
from dicetrace.core import kernels  # noqa: E402
from dicetrace.core.kernels import kernels_for  # noqa: E402
from dicetrace.core.loop import BatchOut, RollOut  # noqa: E402
from dicetrace.core.state import MOTION, new_states, new_work  # noqa: E402
from dicetrace.saving import Record, wants_events  # noqa: E402
from dicetrace.status import Status  # noqa: E402

#: Threads per block: the kernels hold up to 255 registers a thread (``benchmarks/bench_ptxas.py``), so blocks of
#: 128 keep several resident.
THREADS_PER_BLOCK = 128


def simulated() -> bool:
    """Whether numba-cuda's simulator stands in for a GPU (``NUMBA_ENABLE_CUDASIM=1``)."""
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


if simulated():
    _compat.simulator_local_records()  # a thread's local records with their fields by name, as on the device

    def _fenced(records):
        """Under the simulator: nothing (see below)."""

else:
    from llvmlite import ir as llvm_ir  # noqa: E402
    from numba import types as numba_types  # noqa: E402
    from numba.cuda.extending import intrinsic  # noqa: E402

    @intrinsic
    def _fenced(typingctx, records):
        """Make a thread's local records (an array) subject to ``_jit.gpu_fence``: their address goes to an empty
        inline assembly statement, so that NVVM can no longer prove that nothing else reads or writes them, and
        must read them again after a fence, which clobbers memory.  No instruction comes of it."""

        def codegen(context, builder, signature, args):
            data = context.make_array(signature.args[0])(context, builder, args[0]).data
            ptr = builder.bitcast(data, llvm_ir.IntType(8).as_pointer())
            asm = llvm_ir.InlineAsm(llvm_ir.FunctionType(llvm_ir.VoidType(), [ptr.type]), "", "l", side_effect=True)
            builder.call(asm, [ptr])
            return context.get_dummy_value()

        return numba_types.void(records), codegen


def device_count() -> int:
    """How many CUDA devices this process sees (1 under the simulator)."""
    return 1 if simulated() else len(cuda.gpus)


def select_device(k: int) -> None:
    """Make device ``k`` this thread's current device (nothing under the simulator)."""
    if not simulated():
        cuda.select_device(k)


#: The one device (and the share of its memory) that this context's batches use: set by :func:`only_device`.
_ONLY: contextvars.ContextVar = contextvars.ContextVar("dicetrace_gpu_only", default=None)


@contextlib.contextmanager
def only_device(k: int, share: float = 1.0):
    """Within the block, batches run on device ``k`` alone and size their chunks to ``share`` of its free memory.

    A Dask worker's chunk task runs in such a block (``dicetrace.scan.dask``),
    so that each worker uses its own GPU, and workers that must share one
    (more workers than GPUs) split its memory.
    """
    if not 0 <= k < device_count():
        raise ValueError(f"device {k} is not one of the {device_count()} CUDA devices this process sees")
    token = _ONLY.set((int(k), float(share)))
    try:
        yield
    finally:
        _ONLY.reset(token)


def device_ids() -> list[int]:
    """The devices a batch started here runs on: every device, or the one an :func:`only_device` block names."""
    only = _ONLY.get()
    return list(range(device_count())) if only is None else [only[0]]


def memory_share() -> float:
    """The share of a device's free memory that a batch started here may size its chunks to (:func:`only_device`)."""
    only = _ONLY.get()
    return 1.0 if only is None else only[1]


#: Host threads, each with its own CUDA stream, that run chunks on one GPU at a time (``DICETRACE_GPU_STREAMS``).
DEFAULT_STREAMS = 2


def streams_per_device() -> int:
    """Chunks in flight on one GPU, each on its own stream: ``DICETRACE_GPU_STREAMS`` (1 or more), default 2.

    With 2, one chunk's copies and the host's work on its results (the
    compaction, the tables) overlap the next chunk's kernel; 1 runs the
    chunks one after the other (a benchmark's baseline).
    """
    text = os.environ.get("DICETRACE_GPU_STREAMS", "").strip()
    if not text:
        return DEFAULT_STREAMS
    if not text.isdigit() or int(text) < 1:
        raise ValueError(f"DICETRACE_GPU_STREAMS must be a whole number >= 1, got {text!r}")
    return int(text)


def device_name() -> str:
    """The device the kernels run on, in words (e.g. 'NVIDIA H200', or the simulator): the first of
    :func:`device_ids`, read without making a CUDA context in the calling thread."""
    if simulated():
        return "numba-cuda simulator"
    name = cuda.gpus[device_ids()[0]].name
    return name.decode() if isinstance(name, bytes) else str(name)


def free_memory() -> int:
    """Free memory of this thread's current device in bytes (the simulator: 2 GiB, a size for tests)."""
    if simulated():
        return 2 << 30
    free, _total = cuda.current_context().get_memory_info()
    return int(free)


def _make_seed_kernel(tag: int):
    """The one-thread-per-throw kernel around the seed path's summary kernel (``fast.roll_summary_sie_in``).

    ``tag``: 60 bits of the kernel digest (``_jit.kernel_digest``), closed
    over so that numba-cuda's disk cache, which keys a kernel on its own
    code and its closure, never loads a kernel compiled from other core
    sources.  A throw not ended after ``budget`` steps stops as
    ``Status.RUNNING`` and keeps nothing (the caller runs it again in the
    held kernel, :func:`_make_loop_kernel`).
    """

    def seed_kernel(ics, off0, kp, cap, status, steps, outcome, nsets, sets, set_steps, budget):
        i = cuda.grid(1)
        if i < ics.shape[0] and tag >= 0:
            off = cuda.local.array((8, 3), float64)
            F = cuda.local.array((8, 3), float64)
            uk = cuda.local.array((8, 3), float64)
            z = cuda.local.array(8, float64)
            P = cuda.local.array(8, float64)
            lo = i * cap
            s, n, o, ns = fast.roll_summary_sie_in(ics[i], off0, kp, sets[lo : lo + cap], set_steps[lo : lo + cap],
                                                   budget, off, F, uk, z, P)
            status[i] = s
            steps[i] = n
            outcome[i] = o
            nsets[i] = ns

    return seed_kernel


def _make_loop_kernel(loops, tag: int, events: bool, held: bool):
    """The one-thread-per-throw kernel around a scheme's run loop (``loop.make_roll``): its summary loop
    (``loops.roll_summary``: the general kernel) or, with ``events``, its events loop (``loops.roll_events``:
    the events kernel); ``loops`` the module of the scheme's kernels (``kernels.kernels_of``), ``tag`` as above.

    Each thread runs its throw in motion and work records in its local
    memory (``core.state``: what its scheme uses, interleaved across a warp
    by the hardware), at most ``budget`` steps: a throw not ended then stops
    as ``Status.RUNNING``, its records lost.  ``held``: the kernel of such
    throws instead, their records in device memory (``S``, ``Wk``, one per
    throw), which a launch with ``resume`` goes on from.  ``rec`` is 0 (see
    the local records below).  ``ev_times`` is
    laid out as ``sets`` (thread i owns ``[i·cap, (i+1)·cap)``); a summary
    loop ignores it (length 0).  The closure holds the module and bools (the
    constant branches are pruned), never a compiled function: numba-cuda's
    disk cache keys on its values.
    """
    events = bool(events)
    held = bool(held)

    def loop_kernel(ics, off0, kp, cap, S_all, Wk_all, status, steps, outcome, nsets, sets, set_steps, ev_times,
                    e0, e1, e2, resume, budget, rec):
        # S_all, Wk_all: the held kernel's records, one per throw (of no rows for the others)
        i = cuda.grid(1)
        if i < ics.shape[0] and tag >= 0 and not (resume and status[i] != Status.RUNNING):  # (held: ended already)
            lo = i * cap
            if held:
                S = S_all[i : i + 1]
                Wk = Wk_all[i : i + 1]
            else:
                # in the thread's local memory; indexed from a run-time value (``rec``, 0), so that NVVM keeps
                # them there, where the hardware interleaves them across the warp, instead of promoting their
                # 1-4 kB of fields to registers (which spilled ~2 kB a thread: benchmarks/bench_ptxas.py), and
                # fenced: read again after each ``gpu_fence`` instead of kept in registers (``core._jit``)
                S = cuda.local.array(1, MOTION)[rec : rec + 1]
                Wk = cuda.local.array(1, loops.scheme.WORK)[rec : rec + 1]
                _fenced(S)
                _fenced(Wk)
            if events:
                out = RollOut(sets[lo : lo + cap], set_steps[lo : lo + cap], ev_times[lo : lo + cap], e0, e1, e2)
                s, n, o, ns = loops.roll_events(ics[i], off0, kp, S, Wk, out, resume, budget)
            else:
                out = RollOut(sets[lo : lo + cap], set_steps[lo : lo + cap], ev_times, e0, e1, e2)
                s, n, o, ns = loops.roll_summary(ics[i], off0, kp, S, Wk, out, resume, budget)
            status[i] = s
            steps[i] = n
            outcome[i] = o
            nsets[i] = ns

    loop_kernel.__name__ = ("events_kernel" if events else "general_kernel") + ("_held" if held else "")
    return loop_kernel


_KERNELS: dict = {}
_KERNELS_LOCK = threading.Lock()


def _kernel(integ: int, seed_path: bool, events: bool = False, held: bool = False):
    """The CUDA dispatcher for integrator ``integ`` (kernel id): the seed kernel, the general one, or (``events``)
    the events kernel; ``held``: its form whose throws keep their records in device memory between launches."""
    loops = kernels_for(integ)
    key = "seed" if seed_path else loops.scheme.__name__ + (".events" if events else "") + (".held" if held else "")
    with _KERNELS_LOCK:  # the threads of a GPU (or of several) share one dispatcher, compiled once
        return _kernel_locked(key, loops, seed_path, events, held)


def _kernel_locked(key: str, loops, seed_path: bool, events: bool = False, held: bool = False):
    if key not in _KERNELS:
        tag = int(kernel_digest()[:15], 16)
        fn = _make_seed_kernel(tag) if seed_path else _make_loop_kernel(loops, tag, events, held)
        short = loops.scheme.__name__.rsplit(".", 1)[-1] if not seed_path else "seed"
        fn.__qualname__ = fn.__name__ = f"{fn.__name__}_{short}"
        _KERNELS[key] = cuda.jit(fn, cache=CACHE)
    return _KERNELS[key]


#: Held while a kernel compiles: its ``-fma=0`` option is set module-wide (``_compat.nvvm_without_fma``), and a
#: thread running another GPU must neither restore it too early nor compile under it.
_COMPILE_LOCK = threading.Lock()


def _launch(kernel, m: int, args, stream) -> None:
    """Launch ``kernel`` over m threads on ``stream``; compile it first, with ``-fma=0`` (or load
    it from the cache).  Every array argument is a device array: the launch copies nothing and returns at once."""
    blocks = (m + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
    sig = tuple(typeof(a) for a in args)
    if not simulated() and sig not in kernel.overloads:
        with _COMPILE_LOCK:
            if sig not in kernel.overloads:
                with _compat.nvvm_without_fma(nvvm):
                    kernel.compile(sig)
    kernel[blocks, THREADS_PER_BLOCK, stream](*args)


def _gather_kernel(per_throw, cap, starts, packed):
    """Thread i copies its throw's entries of a per-set array (the sets, their steps or the events' times:
    ``starts[i+1] - starts[i]`` of them, from ``i * cap``) to ``starts[i]`` of the packed output: only what the
    throws used crosses to the host."""
    i = cuda.grid(1)
    if i < starts.shape[0] - 1:
        a = starts[i]
        lo = i * cap
        for j in range(starts[i + 1] - a):
            packed[a + j] = per_throw[lo + j]


_GATHER = cuda.jit(_gather_kernel, cache=CACHE)


def uses_seed_kernel(kp, off0, integ: int) -> bool:
    """Whether throws of this configuration run the seed kernel (the CPU's specialised kernel applies)."""
    scheme = kernels_for(integ).scheme
    # the seed kernel wraps the seed path's specialised summary: the one scheme whose ``summary`` that is
    return getattr(scheme, "summary", None) is fast.roll_summary_sie and bool(scheme.summary_applies(kp, off0))


def bytes_per_throw(integ: int, cap: int, kp=None, off0=None, record: Record | None = None) -> int:
    """Device memory one throw of a chunk takes: IC, summaries, ``cap`` contact sets, as many packed for the
    host (at most), its offset there and (where ``record`` asks for events) the times of its sets, likewise
    twice.  Its records are in the thread's local memory (the few throws that outlive a slice get theirs in
    device memory apart, ``_run_held``)."""
    return 6 * 8 + 1 + 8 + 1 + 8 + 2 * (5 + (8 if wants_events(record) else 0)) * cap + 8


#: A batch's summaries per throw, as :class:`~dicetrace.core.loop.BatchOut` holds them: (name, dtype).
_SUMMARIES = (("status", np.int8), ("steps", np.int64), ("outcome", np.int8), ("nsets", np.int64))


def _device_out(m: int, cap: int, record: Record | None, make) -> BatchOut:
    """The outputs of ``m`` throws of ``cap`` sets on the device, for what ``record`` asks (event times where it
    asks for events, else of length 0), as ``kernels.batch_out`` makes them on the host: a
    :class:`~dicetrace.core.loop.BatchOut` of device arrays, each made by ``make(name, n, dtype)``."""
    events = wants_events(record)
    return BatchOut(*(make(name, m, dt) for name, dt in _SUMMARIES), make("sets", m * cap, np.uint8),
                    make("set_steps", m * cap, np.int32),
                    make("times", m * cap, np.float64) if events else make("ev_times", 0, np.float64))


class _Buffers:
    """One host thread's CUDA stream and its buffers, device and pinned host, kept from chunk to chunk.

    A buffer grows (it is made anew) when a chunk needs more than it
    holds; a chunk uses its first rows.
    """

    def __init__(self, device: int):
        self.device = device
        self.stream = cuda.stream()
        self._dev: dict = {}
        self._host: dict = {}

    def dev(self, name: str, n: int, dtype, width: int = 0):
        """The first ``n`` rows of device buffer ``name`` (rows of ``width`` where > 0)."""
        have = self._dev.get(name)
        if have is None or len(have) < n:
            shape = (n, width) if width else n
            have = cuda.device_array(shape, dtype)
            self._dev[name] = have
        return have if len(have) == n else have[:n]

    def host(self, name: str, n: int, dtype, width: int = 0):
        """The first ``n`` rows of pinned (page-locked) host buffer ``name``: copies from and to it are asynchronous."""
        have = self._host.get(name)
        if have is None or len(have) < n:
            have = cuda.pinned_array((n, width) if width else n, dtype)
            self._host[name] = have
        return have if len(have) == n else have[:n]


_LOCAL = threading.local()


def _buffers() -> _Buffers:
    """This host thread's stream and buffers on its current device (made on its first chunk there)."""
    dev = 0 if simulated() else cuda.get_current_device().id
    bufs = getattr(_LOCAL, "buffers", None)
    if bufs is None or bufs.device != dev:
        bufs = _LOCAL.buffers = _Buffers(dev)
    return bufs


def run_batch_cuda(ics, off0, kp, integ, cap, record: Record | None = None):
    """``core.kernels.run_batch`` on the GPU, for what ``record`` asks (None, or the exact contact events), its
    contact sets packed: (status, steps, outcome, nsets, sets, set_steps, times, starts), ``times`` the events'
    times packed as the sets (None where ``record`` asks for no events).

    One chunk, on this host thread's stream (:class:`_Buffers`); the caller
    sizes it to the device's memory (:func:`bytes_per_throw`,
    :func:`free_memory`).  Throw i's sets are ``sets[starts[i] :
    starts[i] + nsets[i]]``, end to end in throw order; a throw that filled
    its ``cap`` sets (``Status.BUFFER_FULL``, re-run by the caller with more)
    has none there.  Threads may run chunks on one GPU or several at once;
    under the simulator, which swaps this module's ``cuda`` for a stand-in
    while a kernel runs, one at a time.
    """
    with _SIMULATOR_LOCK if simulated() else contextlib.nullcontext():
        return _run_batch_cuda(ics, off0, kp, integ, cap, record)


_SIMULATOR_LOCK = threading.Lock()


def _run_batch_cuda(ics, off0, kp, integ, cap, record):
    m = len(ics)
    if m == 0:
        return (np.zeros(0, np.int8), np.zeros(0, np.int64), np.zeros(0, np.int8), np.zeros(0, np.int64),
                np.zeros(0, np.uint8), np.zeros(0, np.int32), np.zeros(0) if wants_events(record) else None,
                np.zeros(0, np.int64))
    status, steps, outcome, nsets, sets, set_steps, times, starts = _first_pass(ics, off0, kp, integ, cap, record)
    going = np.nonzero(status == Status.RUNNING)[0]
    if going.size:  # throws not ended within a slice: again from their start, their records kept on the device
        old_used = _used(status, nsets, cap)
        held = _run_held(ics[going], off0, kp, integ, cap, record)
        status[going], steps[going], outcome[going], nsets[going] = held[:4]
        sets, set_steps, times, starts = _merged(old_used, _used(status, nsets, cap), starts, (sets, set_steps, times),
                                                 going, held)
    return status, steps, outcome, nsets, sets, set_steps, times, starts


def _used(status, nsets, cap):
    """How many sets of each throw come back: none for a throw that filled its buffer or has not ended."""
    return np.where((status == Status.BUFFER_FULL) | (status == Status.RUNNING), 0, np.minimum(nsets, cap))


def _merged(old_used, new_used, starts, arrays, going, held):
    """The first pass's packed sets (steps, times: ``arrays``, ``old_used`` per throw from ``starts``) with those
    of the throws ``going`` from the held run (``held``: what :func:`_run_held` returns): (sets, set_steps,
    times, starts), packed end to end in throw order (``new_used`` per throw)."""
    m = len(old_used)
    new_starts = np.zeros(m + 1, np.int64)
    np.cumsum(new_used, out=new_starts[1:])
    owner = np.repeat(np.arange(m), old_used)  # the throw of each entry of the first pass's packed arrays
    pos_old = new_starts[owner] + (np.arange(len(owner)) - starts[owner])
    h_starts = held[7]
    owner_h = np.repeat(np.arange(len(going)), new_used[going])
    pos_held = new_starts[going[owner_h]] + (np.arange(len(owner_h)) - h_starts[owner_h])
    out = []
    for a, h in zip(arrays, held[4:7]):
        if a is None:
            out.append(None)
            continue
        b = np.empty(int(new_starts[-1]), a.dtype)
        b[pos_old] = a
        b[pos_held] = h
        out.append(b)
    return (*out, new_starts[:-1])


def _first_pass(ics, off0, kp, integ, cap, record):
    """One chunk through the seed kernel or the scheme's kernel in local records, ``kernels.SLICE_STEPS`` steps a
    throw at most, on this host thread's stream; its sets packed (none for throws that have not ended)."""
    m = len(ics)
    events = wants_events(record)  # the kernel chosen from the request: its compile-time flag
    seed_path = not events and uses_seed_kernel(kp, off0, integ)
    kernel = _kernel(integ, seed_path, events)
    buf = _buffers()
    stream = buf.stream
    # in: the ICs and the offsets, through pinned buffers (asynchronous copies on this thread's stream)
    h_ics, h_off0 = buf.host("ics", m, np.float64, 6), buf.host("off0", 8, np.float64, 3)
    h_ics[:] = ics
    h_off0[:] = off0
    d_ics, d_off0 = buf.dev("ics", m, np.float64, 6), buf.dev("off0", 8, np.float64, 3)
    d_ics.copy_to_device(h_ics, stream=stream)
    d_off0.copy_to_device(h_off0, stream=stream)
    out = _device_out(m, cap, record, buf.dev)
    if seed_path:  # the seed kernel writes the summaries and the sets (never events)
        args = (d_ics, d_off0, kp, cap, *out[:6], kernels.SLICE_STEPS * kernels.SUMMARY_SLICES)
    else:  # the loop kernel: no records in device memory (they are the thread's own) and no trace
        args = (d_ics, d_off0, kp, cap, buf.dev("no_motion", 0, MOTION), buf.dev("no_work", 0, kernels_for(integ).scheme.WORK),
                *out, *_no_trace(buf), False, kernels.SLICE_STEPS, 0)
    _launch(kernel, m, args, stream)
    # out: the summaries first, then only the contact sets the throws used
    hosts = [buf.host(name, m, dt) for name, dt in _SUMMARIES]
    for dev, host in zip(out[:4], hosts):
        dev.copy_to_host(host, stream=stream)
    stream.synchronize()
    status, steps, outcome, nsets = (h.copy() for h in hosts)
    starts = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(_used(status, nsets, cap), out=starts[1:])
    total = int(starts[-1])
    sets, set_steps = np.empty(total, np.uint8), np.empty(total, np.int32)
    times = np.empty(total) if events else None
    if total:
        h_starts = buf.host("starts", m + 1, np.int64)
        h_starts[:] = starts
        d_starts = buf.dev("starts", m + 1, np.int64)
        d_starts.copy_to_device(h_starts, stream=stream)
        per_set = [("sets", out.sets, sets), ("steps", out.set_steps, set_steps)]
        if events:
            per_set.append(("times", out.ev_times, times))
        hosts = []
        for name, d_all, out in per_set:
            d_packed = buf.dev(f"packed_{name}", total, out.dtype)
            _launch(_GATHER, m, (d_all, cap, d_starts, d_packed), stream)
            hosts.append(buf.host(f"packed_{name}", total, out.dtype))
            d_packed.copy_to_host(hosts[-1], stream=stream)
        stream.synchronize()
        for (_, _, out), host in zip(per_set, hosts):
            out[:] = host
    return status, steps, outcome, nsets, sets, set_steps, times, starts[:-1]


def _no_trace(buf):
    """The trace arrays of no rows a summary or events loop takes (device arrays)."""
    return (buf.dev("tr_state", 0, np.float64, loop.STATE_COLS), buf.dev("tr_force", 0, np.float64, loop.FORCE_COLS),
            buf.dev("tr_energy", 0, np.float64, loop.ENERGY_COLS))


def _run_held(ics, off0, kp, integ, cap, record):
    """Throws that did not end within a slice, from their start, their records in device memory: launch after launch
    of ``kernels.SLICE_STEPS`` steps a throw until every one has ended (Python runs between launches: Ctrl-C stops them).
    Returns what :func:`_first_pass` returns, for these throws."""
    m = len(ics)
    events = wants_events(record)  # the kernel chosen from the request: its compile-time flag
    kernel = _kernel(integ, False, events, held=True)
    buf = _buffers()
    stream = buf.stream
    d = {name: cuda.to_device(a, stream=stream) for name, a in (
        ("ics", np.ascontiguousarray(ics)), ("off0", np.ascontiguousarray(off0)), ("S", new_states(m)),
        ("Wk", new_work(kernels_for(integ).scheme.WORK, m)))}
    out = _device_out(m, cap, record, lambda name, n, dt: cuda.to_device(np.zeros(n, dt), stream=stream))
    resume = False
    while True:
        _launch(kernel, m, (d["ics"], d["off0"], kp, cap, d["S"], d["Wk"], *out, *_no_trace(buf), resume,
                            kernels.SLICE_STEPS, 0), stream)
        status = out.status.copy_to_host(stream=stream)
        stream.synchronize()
        if not np.any(status == Status.RUNNING):
            break
        resume = True
    steps, outcome, nsets = (a.copy_to_host(stream=stream) for a in (out.steps, out.outcome, out.nsets))
    flat = [out.sets.copy_to_host(stream=stream), out.set_steps.copy_to_host(stream=stream)]
    if events:
        flat.append(out.ev_times.copy_to_host(stream=stream))
    stream.synchronize()
    used = _used(status, nsets, cap)
    keep = (np.arange(cap)[None, :] < used[:, None]).ravel()
    starts = np.zeros(m + 1, np.int64)
    np.cumsum(used, out=starts[1:])
    packed = [a[keep] for a in flat]
    return status, steps, outcome, nsets, packed[0], packed[1], packed[2] if events else None, starts[:-1]
