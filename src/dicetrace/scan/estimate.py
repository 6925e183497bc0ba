"""What a scan will cost before it starts: time (by calibration), disk and chunk memory.

Disk and memory go by the IC, with fixed figures measured on the writeup's
windows (``BYTES_PER_IC`` ..., which hold up to ``TYPICAL_SETS`` contact sets
per IC), and by the contact set beyond those: a throw that never settles
(no damping, a long time cap) can record millions of sets -- with exact
events, millions of events, each with its time.  Where the scan is large
enough to be calibrated, the probe that times it also counts the sets of
its throws (extrapolated to the time cap for the throws the probe cut
short) and the estimate adds what sets beyond ``TYPICAL_SETS`` take: an
upper bound of the real files (``BYTES_PER_SET``, ``BYTES_PER_SET_EVENTS``)
and of the memory a chunk of them holds in flight.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numba
import numpy as np

from dicetrace.scan.definition import ScanDefinition
from dicetrace.simulate import simulate_batch
from dicetrace.sinks._common import free_bytes, human_bytes

from dicetrace.scan.chunk_files import chunk_files
from dicetrace.scan.folder import _check_int, has_manifest

#: Bytes on disk per IC, a round upper estimate (measured 80–110 on the writeup's windows).
BYTES_PER_IC = 128
#: The same with exact contact events (``contact_times_s``: a float64 per set; measured 450–470 on three windows
#: of `physical` at 128²).
BYTES_PER_IC_EVENTS = 640
#: Bytes on disk per chunk file beyond its rows (Parquet footer, the definition in its metadata; measured ~11 KiB).
BYTES_PER_CHUNK = 16 * 1024
#: Memory per IC of a chunk in flight, bytes (contact-set buffers, summaries, the Arrow table).
MEMORY_PER_IC = 1024
#: The same with exact contact events (a float64 time beside each of the ``cap`` buffered sets).
MEMORY_PER_IC_EVENTS = 2048
#: Contact sets per IC that the figures above hold (measured means on the writeup's windows at 48²: 28 for
#: `seed`, 44 for `physical`, 49 with exact events, at 80, 102 and 465 bytes per IC on disk).
TYPICAL_SETS = 64
#: Bytes on disk per contact set beyond ``TYPICAL_SETS``, upper bounds: the set (a byte), its text in
#: ``contact_sequence`` and, with exact events, its time (a float64 that compresses little).  Measured on a throw
#: that never settles (``physical``, gamma = mu = 0, 10⁴ s): 1.3 bytes per set, 8.4 per event.
BYTES_PER_SET = 4
BYTES_PER_SET_EVENTS = 12
#: Memory per contact set beyond ``TYPICAL_SETS`` of a chunk in flight: the kernel's buffer (5 bytes a set, 13
#: with its time) up to ``CAP_GROWTH`` = 8 times the sets (a throw that fills it runs again with 8 times as
#: many), their packed copy, the Arrow table and its encoding.  Measured: 86 bytes per event at 238,000 events.
MEMORY_PER_SET = 64
MEMORY_PER_SET_EVENTS = 160
#: Memory to draw a scan's map (``--png``, ``--rrd``: the whole scan is read), bytes: per IC (measured 120 for the
#: PNG and 230 for the recording at 600², rounded up) and beyond the ICs (measured ~60 MiB).
MAP_MEMORY_PER_IC = 512
MAP_MEMORY_BASE = 128 << 20
#: Memory of the whole rolls table held in memory (``scan(space)`` without a folder), bytes per IC (measured 260 for
#: the table; the chunks and their concatenation are held at once).
TABLE_MEMORY_PER_IC = 640
#: The same with exact contact events (measured 730 for the table).
TABLE_MEMORY_PER_IC_EVENTS = 2048
#: Memory of one worker process of a local Dask cluster beyond its chunk (an interpreter with numba, pyarrow and
#: the kernels loaded), bytes.
DASK_WORKER_MEMORY = 256 << 20


# -- estimating -------------------------------------------------------------------------------


#: Calibration: ICs sampled across the space, and the steps each may take.
CALIBRATION_ICS = 48
CALIBRATION_STEPS = 20_000
#: The timed probe is repeated until it has run CALIBRATION_MIN_S seconds and CALIBRATION_MIN_REPS times, or for
#: CALIBRATION_MAX_S seconds (one run of a slow scheme may take that long).
CALIBRATION_MIN_S = 0.5
CALIBRATION_MIN_REPS = 10
CALIBRATION_MAX_S = 2.0
#: Slowest step of any integrator, s (a pessimistic bound used to skip calibrating tiny scans).
SLOWEST_STEP_S = 2e-6


@dataclass(frozen=True)
class ScanEstimate:
    """What a scan run would cost, before it starts (:func:`estimate_scan`).

    ``seconds`` is the estimated wall time of this run on ``threads``
    threads (None when the run is too small to be worth timing: at most
    ``seconds_bound``); ``upper`` says the estimate assumes that the sampled
    throws which had not ended within the calibration's steps run to the
    time cap.  ``bytes`` is the estimated size on disk of the new chunks.
    """

    n_ics: int
    n_chunks: int
    chunks_todo: int
    ics_todo: int
    bytes: int
    free_bytes: int | None
    chunk_memory: int
    threads: int
    seconds: float | None
    seconds_bound: float
    upper: bool = False
    #: The machine's load (threads running besides the probe) when it was calibrated, where it slows the scan down
    #: (else None).
    load: float | None = None
    #: The device the scan runs on (its definition's); on a GPU the time is not estimated (``seconds`` None).
    device: str = "cpu"
    #: Contact sets per IC the probe measured (mean, extrapolated to the time cap; None: not probed, the fixed
    #: figures apply); ``bytes`` and ``chunk_memory`` count those beyond ``TYPICAL_SETS``.
    sets_per_ic: float | None = None
    #: Memory of one IC's row in flight, bytes (a chunk holds ``min(chunk, n_ics)`` of them).
    ic_memory: int = 0

    def describe(self) -> str:
        free = "" if self.free_bytes is None else f", {human_bytes(self.free_bytes)} free"
        if self.device != "cpu":
            return (f"{self.ics_todo:,} ICs in {self.chunks_todo:,} chunks to compute (of {self.n_ics:,}) on "
                    f"{self.device} (time not estimated on a GPU), about {human_bytes(self.bytes)} on disk{free}")
        t = self.seconds if self.seconds is not None else self.seconds_bound
        when = f"{'at most ' if self.seconds is None or self.upper else 'about '}{human_seconds(t)}"
        busy = "" if self.load is None else f" at the machine's present load ({self.load:.1f})"
        sets = ("" if self.sets_per_ic is None or self.sets_per_ic <= TYPICAL_SETS else
                f" ({self.sets_per_ic:,.0f} contact sets per IC on a probe)")
        return (f"{self.ics_todo:,} ICs in {self.chunks_todo:,} chunks to compute (of {self.n_ics:,}): "
                f"{when} on {self.threads} thread(s){busy}, about {human_bytes(self.bytes)} on disk{sets}{free}")


def human_seconds(s: float) -> str:
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    if s < 2 * 86400:
        return f"{s / 3600:.1f} h"
    if s < 2 * 365 * 86400:
        return f"{s / 86400:.0f} days"
    return f"{s / (365.25 * 86400):.3g} years"


def estimate_scan(defn: ScanDefinition, out=None, *, threads: int | None = None, max_chunks: int | None = None,
                  calibrate: bool = True) -> ScanEstimate:
    """Estimate a scan run (time, disk, memory per chunk) before starting it.

    Counts the chunks ``out`` already holds (by name; nothing is verified or
    written), then, unless the run is certainly short, times up to
    ``CALIBRATION_ICS`` ICs spread over the space with the scan's
    configuration, each limited to ``CALIBRATION_STEPS`` steps (a throw not
    ended by then is counted at the full time cap: the estimate is then an
    upper one).  Only warm throughput is timed: the probe runs once untimed
    first, which compiles (or loads) the kernels the scan needs -- on a
    fresh install or with ``DICETRACE_CACHE=0`` that first run takes the
    compile's time, which the scan then does not spend again.  The same
    probe counts its throws' contact sets (``sets_per_ic``: a throw cut
    short counted at the rate it had, to the time cap), and the disk and
    memory estimates add those beyond ``TYPICAL_SETS``.  A scan on a GPU
    (``defn.device``) is not probed: the probe times the CPU's threads.
    """
    if not isinstance(defn, ScanDefinition):
        raise TypeError(f"defn must be a ScanDefinition, not {type(defn).__name__}")
    _check_int(threads, "threads", 1)
    _check_int(max_chunks, "max_chunks", 0)
    n_done = 0
    if out is not None and Path(out).is_dir() and has_manifest(out):
        n_done = sum(1 for c in chunk_files(out) if c < defn.n_chunks)
    chunks_todo = defn.n_chunks - n_done
    if max_chunks is not None:
        chunks_todo = min(chunks_todo, max_chunks)
    ics_todo = min(defn.size, chunks_todo * defn.chunk)  # at most: the last chunk may be short
    nthreads = threads or numba.get_num_threads()
    max_steps = defn.config.numerics.max_steps
    bound = ics_todo * max_steps * SLOWEST_STEP_S / nthreads
    free = free_bytes(_existing_parent(Path(out) if out is not None else Path.cwd()))
    disk_per_ic, memory_per_ic = (BYTES_PER_IC_EVENTS, MEMORY_PER_IC_EVENTS) if defn.events else (BYTES_PER_IC, MEMORY_PER_IC)
    est = ScanEstimate(
        n_ics=defn.size, n_chunks=defn.n_chunks, chunks_todo=chunks_todo, ics_todo=ics_todo,
        bytes=ics_todo * disk_per_ic + chunks_todo * BYTES_PER_CHUNK, free_bytes=free,
        chunk_memory=min(defn.chunk, defn.size) * memory_per_ic,
        threads=nthreads, seconds=None, seconds_bound=bound, device=defn.device, ic_memory=memory_per_ic,
    )
    if not calibrate or bound <= 30.0 or ics_todo == 0 or defn.device != "cpu":
        return est
    n = min(CALIBRATION_ICS, defn.size)
    ids = sorted({int(round(v)) for v in np.linspace(0, defn.size - 1, n)})
    blocks = [defn.block(i, i + 1) for i in ids]
    ics = np.concatenate([b.ics for b in blocks]).reshape(-1, 6)
    poses = {}
    if defn.posed:  # each throw from its own pose, as the scan throws it
        poses = {"orientations": np.concatenate([b.orientations for b in blocks]),
                 "heights_cm": np.concatenate([b.heights_cm for b in blocks])}
    num = defn.config.numerics
    cal_steps = min(max_steps, CALIBRATION_STEPS)
    cal = replace(defn.config, numerics=replace(num, t_max_s=min(num.t_max_s, cal_steps * num.dt_s)))
    conv = defn.l_convention

    def probe():
        return simulate_batch(ics, config=cal, l_convention=conv, threads=1, record=defn.record, **poses)

    # Warm throughput only: the first run compiles (or loads from the cache) every kernel these throws reach --
    # numba compiles some only when a throw first needs them -- and is not timed.  Then the probe is timed over
    # at least CALIBRATION_MIN_S and CALIBRATION_MIN_REPS runs: one run of a millisecond says little on a busy
    # machine, where a run now and then waits for the processor; their mean is the throughput the scan will see.
    res = probe()
    reps, t0, cpu0, others = 0, time.perf_counter(), time.process_time(), []
    while True:
        probe()
        reps += 1
        others.append(_running_besides_us())
        elapsed = time.perf_counter() - t0
        if elapsed >= CALIBRATION_MAX_S or (elapsed >= CALIBRATION_MIN_S and reps >= CALIBRATION_MIN_REPS):
            break
    cpu = (time.process_time() - cpu0) / reps  # processor time: a probe a busy machine put aside costs none
    steps = res.steps.astype(np.float64)
    capped = (steps >= cal.numerics.max_steps) & (cal.numerics.max_steps < max_steps)
    full = np.where(capped, float(max_steps), steps)
    per_ic = cpu / len(ids) * (full.sum() / max(steps.sum(), 1.0))
    fast_steps = _fast_slice(cal)
    if capped.any() and fast_steps is not None and max_steps > fast_steps and not defn.posed:
        # the seed path's specialised kernel gives a throw past its long slice to the run loop, whose steps cost
        # more: the steps beyond that slice are costed at the loop's rate, timed on the capped throws
        per_step = cpu / max(steps.sum(), 1.0)
        loop_step = _loop_step_seconds(ics[capped], cal, conv)
        per_ic += capped.sum() / len(ids) * (max_steps - fast_steps) * max(loop_step - per_step, 0.0)
    seen = [x for x in others if x is not None]
    cores, load = effective_cores(nthreads, sum(seen) / len(seen) if seen else None)
    est = _with_sets(est, defn, res, full / np.maximum(steps, 1.0))
    return replace(est, seconds=ics_todo * per_ic / cores, upper=bool(capped.any()), load=load)


def _fast_slice(cfg) -> int | None:
    """The steps the specialised summary kernel takes before it gives a throw to the run loop, where it applies
    to ``cfg`` (the seed path), else None."""
    from dicetrace.core.kernels import SLICE_STEPS, SUMMARY_SLICES, kernels_for  # lazy: imports numba

    kin = cfg.kernel_inputs(np.zeros((0, 6)))
    scheme = kernels_for(kin.integrator_id).scheme
    if hasattr(scheme, "summary") and scheme.summary_applies(kin.params, kin.off0):
        return SLICE_STEPS * SUMMARY_SLICES
    return None


def _loop_step_seconds(ics: np.ndarray, cfg, conv: str) -> float:
    """Processor seconds a step of the run loop costs on these throws (each run to the probe's step limit)."""
    from dicetrace.params import convert_l
    from dicetrace.simulate import simulate

    ics = convert_l(ics[:8], conv, cfg.preset.l_convention)
    simulate(ics[0], config=cfg)  # loads (or compiles) the loop, untimed
    t0 = time.process_time()
    n = sum(simulate(ic, config=cfg).steps for ic in ics)
    return (time.process_time() - t0) / max(n, 1)


def _with_sets(est: ScanEstimate, defn: ScanDefinition, probe, stretch: np.ndarray) -> ScanEstimate:
    """``est`` with the contact sets the probe's throws recorded: each throw's count times ``stretch`` (its steps
    to the time cap over the steps the probe ran: 1 where it ended within them), their mean counted beyond
    ``TYPICAL_SETS`` in the disk and the memory per IC."""
    sets = float((np.diff(probe.set_offsets) * stretch).mean())
    extra = max(0.0, sets - TYPICAL_SETS)
    per_set_disk, per_set_memory = ((BYTES_PER_SET_EVENTS, MEMORY_PER_SET_EVENTS) if defn.events else
                                    (BYTES_PER_SET, MEMORY_PER_SET))
    ic_memory = est.ic_memory + int(extra * per_set_memory)
    return replace(est, sets_per_ic=sets, bytes=est.bytes + int(est.ics_todo * extra * per_set_disk),
                   ic_memory=ic_memory, chunk_memory=min(defn.chunk, defn.size) * ic_memory)


def _running_besides_us() -> float | None:
    """Threads running or runnable on the machine now, besides the one reading (Linux ``/proc/loadavg``; else None)."""
    try:
        with open("/proc/loadavg") as f:
            return max(0.0, float(f.read().split()[3].split("/")[0]) - 1.0)
    except (OSError, ValueError, IndexError):
        return None


def effective_cores(threads: int, others: float | None = None) -> tuple[float, float | None]:
    """The processors ``threads`` threads of a scan will get: (cores, the load that limits them or None).

    ``min(threads, cpus)`` on an idle machine; on a busy one, with L
    threads running or waiting besides the scan's own, each gets
    ``cpus / (L + threads)`` of a processor.  L is ``others`` (counted
    while the probe ran), else the 1-minute load average (which lags: it
    still counts work that has just ended).  Timing a probe of a
    millisecond or so by the wall clock instead tells little: a thread
    that has just woken gets more than its share for a while.
    """
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 1
    n = max(1, min(threads, cpus))
    load = others
    if load is None:
        try:
            load = max(0.0, os.getloadavg()[0])
        except (AttributeError, OSError):
            return float(n), None
    share = min(1.0, cpus / (load + n))
    return n * share, (load if share < 0.9 else None)


def _existing_parent(p: Path) -> Path:
    p = p.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p

