"""Running :func:`~dicetrace.simulate.simulate_batch` chunk by chunk: the contact-set buffers, the
size of a chunk, the check that a batch fits in memory, and the kernel calls with their buffer growth.

Each chunk's ICs go through the batch kernel (``run_batch``; up to one kernel
block, ``BATCH_BLOCK``, through the single-throw loop instead) with ``cap``
contact sets per IC; throws that fill their buffer are re-run with
``CAP_GROWTH`` times more until they fit, and the chunk's sets are compacted.
What the throws keep besides their summaries is the batch's request, a
:class:`~dicetrace.saving.Record` asking for the exact contact events, or
None (a batch keeps no trace): it goes on as it is to the kernels' entry
points, which choose their loop from it.
"""

from __future__ import annotations

import collections
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

import numba

from dicetrace.core.kernels import batch_out, run_batch, run_throw, throw_out
from dicetrace.core.loop import BATCH_BLOCK
from dicetrace.devices import CPU, Device
from dicetrace.memory import available_memory
from dicetrace.saving import Record, wants_events
from dicetrace.status import Status

#: Contact sets per IC in the first pass (longer throws are re-run with ``CAP_GROWTH`` times more).
DEFAULT_CAP = 128
CAP_GROWTH = 8
#: Largest first-pass buffer a caller may ask for, contact sets per IC.
MAX_CAP = 2**31 - 1


class _Threads:
    """Context: numba threads for this thread's parallel regions (None: leave as is)."""

    def __init__(self, n: int | None):
        self.n = n

    def __enter__(self):
        self.old = numba.get_num_threads()
        if self.n is not None:
            numba.set_num_threads(max(1, min(int(self.n), numba.config.NUMBA_NUM_THREADS)))

    def __exit__(self, *exc):
        numba.set_num_threads(self.old)


def _run_batch(kin, cap: int, threads, device: Device = CPU, record: Record | None = None):
    """One call of the batch kernel over ``kin.ics`` with ``cap`` sets per IC, on ``device`` ("cpu" or "cuda"):
    (status, steps, outcome, nsets, sets, set_steps, times, starts), throw i's sets from ``starts[i]``.

    ``record`` asking for events: the events kernels (exact contact events),
    whose event times are ``times`` (laid out as ``sets``); None without.

    On the CPU the sets are the kernel's buffers (``cap`` per throw,
    ``starts[i] = i * cap``); on the GPU they come back packed, without the
    sets of a throw that filled its buffer (``core.gpu.run_batch_cuda``).
    On the CPU, up to ``BATCH_BLOCK`` ICs (one work item of the batch
    kernel, so one thread either way) run one by one through the
    single-throw loop instead: the same results bit for bit, without
    compiling the batch kernel for them (a first ``dicetrace simulate --ic``
    compiles a third as much).
    """
    m = len(kin.ics)
    if device.gpu:
        from dicetrace.core.gpu import run_batch_cuda  # numba-cuda: optional, imported only for a GPU run

        return run_batch_cuda(kin.ics, kin.off0, kin.params, kin.integrator_id, cap, record)
    starts = np.arange(m, dtype=np.int64) * cap
    out = batch_out(m, cap, record)
    if m <= BATCH_BLOCK:
        _run_serial(kin, cap, out, record)
    else:
        with _Threads(threads), numba.parallel_chunksize(1):
            run_batch(kin.ics, kin.off0, kin.params, kin.integrator_id, cap, out, record)
    return (*out[:6], out.ev_times if wants_events(record) else None, starts)


def _run_serial(kin, cap: int, out, record: Record | None = None) -> None:
    """What ``run_batch`` writes to ``out`` (``kernels.batch_out``), from the single-throw loop
    (``kernels.run_throw``) called IC by IC."""
    for i in range(len(kin.ics)):
        r = run_throw(kin.ics[i], kin.off0, kin.params, kin.integrator_id, throw_out(out, i, cap), record)
        out.status[i], out.steps[i], out.outcome[i], out.nsets[i] = r


#: Bytes a batch's result holds per IC whatever its throws: status and outcome (1 each);
#: steps, t_settle_s, set_offsets and the set counts (8 each); at least one contact set (1, and 4 for its step).
RESULT_BYTES_PER_IC = 1 + 1 + 8 + 8 + 8 + 8 + 5
#: Bytes per IC of a chunk in flight besides its contact-set buffers (``cap`` sets of 1 + 4 bytes, and
#: a 1-byte mask): the kernel's copy of the ICs (48), its outputs (1 + 8 + 1 + 8), their compacted copy.
CHUNK_BYTES_PER_IC = 48 + 18 + 18
#: Working memory of one chunk of :func:`simulate_batch` when no ``chunk`` is given.
CHUNK_BYTES = 64 * 2**20


def chunk_bytes_per_ic(cap: int, record: Record | None = None) -> int:
    """Bytes per IC of a chunk in flight: ``CHUNK_BYTES_PER_IC`` and its ``cap`` sets (with their times, 8 bytes
    each, where ``record`` asks for events)."""
    return CHUNK_BYTES_PER_IC + (14 if wants_events(record) else 6) * cap


def batch_chunk(cap: int = DEFAULT_CAP, record: Record | None = None) -> int:
    """ICs per chunk of :func:`simulate_batch` by default: about ``CHUNK_BYTES`` of buffers, whole kernel blocks."""
    n = CHUNK_BYTES // chunk_bytes_per_ic(cap, record)
    return max(BATCH_BLOCK, n // BATCH_BLOCK * BATCH_BLOCK)


#: Most ICs per chunk on a GPU (2²⁰: several times the threads an H200 keeps resident).
GPU_CHUNK_MAX = 2**20
#: Share of a GPU's free memory that the chunks in flight on it (one per stream) may take together.
GPU_MEMORY_SHARE = 0.8


def gpu_batch_chunk(kin, cap: int = DEFAULT_CAP, record: Record | None = None) -> int:
    """ICs per chunk on the GPU by default: at most ``GPU_CHUNK_MAX``, one stream's part of
    ``GPU_MEMORY_SHARE`` of the free memory of the GPU it runs on (of this Dask worker's part of it, where
    workers share one: ``core.gpu.memory_share``), and 16 times the CPU's chunk of host buffers."""
    from dicetrace.core import gpu  # numba-cuda: optional, imported only for a GPU run

    streams = gpu.streams_per_device()
    per = gpu.bytes_per_throw(kin.integrator_id, cap, kin.params, kin.off0, record) * streams
    # asked in a thread of that GPU's pool: a thread has one CUDA device, and this one may never have had one
    free = _gpu_pool(gpu.device_ids()[0], streams).submit(gpu.free_memory).result() * gpu.memory_share()
    n = min(GPU_CHUNK_MAX, int(GPU_MEMORY_SHARE * free) // per, 16 * batch_chunk(cap, record))
    return max(BATCH_BLOCK, n)


def check_batch_memory(m: int, cap: int, chunk: int, *, ics_copy: bool = False, what: str = "simulate_batch",
                       record: Record | None = None) -> None:
    """Refuse (ValueError naming ``what``, the size and the limit) a batch that cannot fit in the available memory.

    Counts what the result must hold whatever the throws (``RESULT_BYTES_PER_IC``,
    48 more per IC when the ICs are returned converted, ``ics_copy``) and one
    chunk in flight; the contact sets beyond the first of each throw (about
    5 bytes each, 20–70 a throw) come on top, so this is a lower bound.
    """
    result = m * (RESULT_BYTES_PER_IC + (48 if ics_copy else 0))
    flight = min(m, chunk) * chunk_bytes_per_ic(cap, record)
    avail = available_memory()
    if avail is not None and result + flight > avail:
        gib = 2**30
        raise ValueError(
            f"{what}: {m:,} ICs need at least {(result + flight) / gib:.3g} GiB ({result / gib:.3g} GiB for their results, "
            f"more with their contact sets, and {flight / gib:.3g} GiB for a chunk of {min(m, chunk):,} ICs with cap {cap:,}), "
            f"more than the {avail / gib:.3g} GiB of memory available: pass fewer ICs per call"
            + (" or a smaller chunk or cap" if flight > result else "")
            + " (a scan writes its rows to disk chunk by chunk)"
        )


def run_chunk(kin, cap: int, threads, device: Device = CPU, record: Record | None = None):
    """Summaries of the ICs of ``kin``: (status, steps, outcome, nsets, sets, set_steps, times), sets compacted.

    Throws that fill their ``cap`` sets are re-run, all together, with
    ``CAP_GROWTH`` times more until they fit, on the same ``device``.
    ``record`` asking for events: the exact contact events (``_run_batch``),
    their times in ``times`` (None without).
    """
    m = len(kin.ics)
    status, steps, outcome, nsets, sets, set_steps, times, starts = _run_batch(kin, cap, threads, device, record)
    arrays = (sets, set_steps) if times is None else (sets, set_steps, times)
    extra: dict[int, tuple] = {}
    todo = np.nonzero(status == Status.BUFFER_FULL)[0]
    big = cap
    while todo.size:
        big *= CAP_GROWTH
        st, sp, oc, ns, *more, at = _run_batch(kin._replace(ics=kin.ics[todo]), big, threads, device, record)
        more = [a for a in more if a is not None]
        done = st != Status.BUFFER_FULL
        for r in np.nonzero(done)[0]:
            i = todo[r]
            status[i], steps[i], outcome[i], nsets[i] = st[r], sp[r], oc[r], ns[r]
            extra[int(i)] = tuple(a[at[r] : at[r] + ns[r]].copy() for a in more)
        todo = todo[~done]
    if not extra:
        if len(sets) == int(nsets.sum()):  # packed already (the GPU's)
            return status, steps, outcome, nsets, sets, set_steps, times
        full = np.arange(cap)[None, :] < nsets[:, None]
        packed = [a.reshape(m, cap)[full] for a in arrays]
        return (status, steps, outcome, nsets, *packed[:2], packed[2] if times is not None else None)
    ends = np.cumsum(nsets)
    flat = [np.empty(int(ends[-1]), dtype=a.dtype) for a in arrays]
    for i in range(m):
        a, b = ends[i] - nsets[i], ends[i]
        s0 = starts[i]
        parts = extra[i] if i in extra else tuple(x[s0 : s0 + nsets[i]] for x in arrays)
        for f, part in zip(flat, parts):
            f[a:b] = part
    return (status, steps, outcome, nsets, *flat[:2], flat[2] if times is not None else None)


#: Least ICs of a piece that :func:`chunk_results` cuts a GPU chunk into (so that each GPU has chunks in flight).
GPU_PIECE_MIN = 2**16
#: Most pieces of a GPU chunk per stream: more than one, so that a stream's copies overlap another's kernel
#: through the chunk, not only at its end.
PIECES_PER_STREAM = 4


def _pieces(a: int, b: int, n: int) -> list[tuple[int, int]]:
    """``(a, b)`` cut into up to ``n`` near-equal pieces of at least ``GPU_PIECE_MIN`` ICs (one if it is smaller)."""
    k = max(1, min(n, (b - a) // GPU_PIECE_MIN))
    cuts = [a + (b - a) * j // k for j in range(k + 1)]
    return list(zip(cuts[:-1], cuts[1:]))


def _joined(results: list):
    """One chunk's summaries from those of its pieces, in order."""
    if len(results) == 1:
        return results[0]
    return tuple(None if parts[0] is None else np.concatenate(parts) for parts in zip(*results))


#: Per GPU: the host threads that run its chunks, each with its own CUDA stream (made once per process).
_POOLS: dict = {}
_POOLS_LOCK = threading.Lock()


def _gpu_pool(k: int, streams: int) -> ThreadPoolExecutor:
    """The thread pool of device ``k``: ``streams`` threads, each with device ``k`` current."""
    from dicetrace.core import gpu  # numba-cuda: optional, imported only for a GPU run

    with _POOLS_LOCK:
        pool = _POOLS.get((k, streams))
        if pool is None:
            for key in [key for key in _POOLS if key[0] == k]:  # another number of streams: its threads end when idle
                _POOLS.pop(key).shutdown(wait=False)          # (and with them their buffers)
            pool = _POOLS[(k, streams)] = ThreadPoolExecutor(
                streams, thread_name_prefix=f"dicetrace-gpu{k}", initializer=gpu.select_device, initargs=(k,))
        return pool


def chunk_results(bounds, run, device: Device = CPU):
    """``run(a, b)`` for each ``(a, b)`` of ``bounds``, yielded in order.

    On the CPU the chunks run one after the other here.  On GPUs
    (``device.gpu``) each chunk is cut into pieces (at least
    ``GPU_PIECE_MIN`` ICs each, at most ``PIECES_PER_STREAM`` per stream)
    so that every GPU has work, and the pieces go
    round-robin to the GPUs (``core.gpu.device_ids``: every device, or the
    one a Dask worker was given), each GPU's to its own threads, one CUDA
    stream each (``core.gpu.streams_per_device``): while one piece's results
    are copied back and packed, the next one's ICs are copied in and its
    kernel runs.  At most two pieces per stream (or one chunk's pieces) are
    queued beyond the chunk being yielded.
    Every piece runs the same kernels from its own ICs, so the results are
    those of one GPU running the chunks one by one.
    """
    if not device.gpu:
        for a, b in bounds:
            yield run(a, b)
        return
    from dicetrace.core import gpu  # numba-cuda: optional, imported only for a GPU run

    devices, streams = gpu.device_ids(), gpu.streams_per_device()
    pools = [_gpu_pool(k, streams) for k in devices]
    lanes = len(devices) * streams
    pending: collections.deque = collections.deque()  # (chunk number, future)
    turn = 0
    try:
        for c, (a, b) in enumerate(bounds):
            for lo, hi in _pieces(a, b, PIECES_PER_STREAM * lanes):
                pending.append((c, pools[turn % len(pools)].submit(run, lo, hi)))
                turn += 1
                while len(pending) > 2 * lanes and pending[0][0] != c:  # the first chunk is all queued
                    yield _first_chunk(pending)
        while pending:
            yield _first_chunk(pending)
    finally:
        for _, fut in pending:
            fut.cancel()


def _first_chunk(pending: collections.deque):
    """The summaries of the first chunk in ``pending`` (all its pieces are queued), once its pieces are done."""
    c = pending[0][0]
    results = []
    while pending and pending[0][0] == c:
        results.append(pending.popleft()[1].result())
    return _joined(results)


def join_parts(parts: list, dtype, total: int) -> np.ndarray:
    """The parts end to end, each part freed once copied (peak: the whole plus one part)."""
    if len(parts) == 1:
        return parts.pop()
    out = np.empty(total, dtype=dtype)
    pos = 0
    while parts:
        p = parts.pop(0)
        out[pos : pos + len(p)] = p
        pos += len(p)
    return out

