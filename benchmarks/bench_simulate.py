"""Throughput of the simulator kernel on the seed slice, x, y ∈ [0, 20].

Prints throws/s and ns per simulated step for

* the run loop on the scheme's step (``kernels.run_roll``'s tracing loop,
  ``semi_implicit_euler.roll_trace``, with no trace rows: every step through
  ``semi_implicit_euler.step``, as every throw ran before the specialised
  kernel; serial, one core),
* the batch kernel (``kernels.run_batch``: the specialised kernel
  ``fast.roll_summary_sie`` over a prange) with 1 and 2 threads (or
  ``--threads``),
* ``simulate_batch`` (the Python API around it) with all threads.

Usage: ``python benchmarks/bench_simulate.py [--n 20000] [--threads 1,2]``.
Wall time and process CPU time are both printed: on a shared machine the
CPU-time rate per thread is the steadier figure.
"""

from __future__ import annotations

import argparse
import os
import time

import numba
import numpy as np

from dicetrace.core.kernels import NO_TRACE, batch_out, new_roll_state, roll_kernel, run_batch
from dicetrace.core.loop import RollOut
from dicetrace.ics import seed_slice
from dicetrace.params import make_config
from dicetrace.simulate import simulate_batch


@numba.njit(cache=False)  # takes a compiled kernel as an argument: nothing to cache
def _general_loop(roll, ics, off0, kp, S, Wk, steps, e0, e1, e2):
    """``roll`` (the tracing loop, what ``kernels.run_roll`` calls) on every IC, with no trace rows, in one call each."""
    sets = np.zeros(4096, np.uint8)
    set_steps = np.zeros(4096, np.int32)
    out = RollOut(sets, set_steps, np.zeros(0), e0, e1, e2)
    for i in range(ics.shape[0]):
        s, n, o, ns = roll(ics[i], off0, kp, S, Wk, out, False, 1 << 62)
        steps[i] = n


def _timed(fn, repeat):
    best_wall, best_cpu = np.inf, np.inf
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        fn()
        best_wall = min(best_wall, time.perf_counter() - w)
        best_cpu = min(best_cpu, time.process_time() - c)
    return best_wall, best_cpu


def _line(label, m, steps, wall, cpu, threads):
    print(
        f"{label:<34} {m / wall:>10,.0f} throws/s {wall * 1e9 / steps:>7.1f} ns/step"
        f"   | {m / cpu:>9,.0f} throws per CPU-second"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=20000, help="ICs (default 20000)")
    ap.add_argument("--threads", default="1,2", help="thread counts for the batch kernel (default 1,2)")
    ap.add_argument("--general", type=int, default=2000,
                    help="ICs for the baseline, the run loop on the scheme's step (default 2000)")
    ap.add_argument("--repeat", type=int, default=3, help="best of this many runs (default 3)")
    args = ap.parse_args()

    rng = np.random.default_rng(1)
    xy = rng.uniform(0.0, 20.0, size=(args.n, 2))
    ics = np.ascontiguousarray(seed_slice(xy[:, 0], xy[:, 1]))
    cfg = make_config("seed")
    kp = cfg.kernel_params()
    off0 = cfg.initial_offsets()
    integ = cfg.kernel_inputs(ics[:0]).integrator_id
    m = len(ics)
    cap = 128
    print(f"seed preset, {m:,} ICs on the seed slice, x, y uniform in [0, 20] (rng 1); "
          f"{os.cpu_count()} CPUs, numba {numba.__version__}, load average {os.getloadavg()[0]:.2f}")

    # the run loop on the scheme's step (kernels.run_roll's tracing loop, no trace rows), serial
    g = ics[: args.general]
    gsteps = np.zeros(len(g), np.int64)
    roll, (S, Wk) = roll_kernel(integ, True), new_roll_state(integ)
    _general_loop(roll, g[:2], off0, kp, S, Wk, gsteps[:2], *NO_TRACE)
    wall, cpu = _timed(lambda: _general_loop(roll, g, off0, kp, S, Wk, gsteps, *NO_TRACE), 1)
    _line(f"run loop on the step, {len(g)} ICs", len(g), gsteps.sum(), wall, cpu, 1)

    out = batch_out(m, cap)

    def batch():
        with numba.parallel_chunksize(1):
            run_batch(ics, off0, kp, integ, cap, out)

    numba.set_num_threads(1)
    run_batch(ics[:16], off0, kp, integ, cap, batch_out(16, cap))
    rates = {}
    for t in [int(v) for v in args.threads.split(",")]:
        t = min(t, numba.config.NUMBA_NUM_THREADS)
        numba.set_num_threads(t)
        wall, cpu = _timed(batch, args.repeat)
        rates[t] = m / wall
        _line(f"run_batch, {t} thread(s)", m, out.steps.sum(), wall, cpu, t)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    if len(rates) > 1:
        t0, t1 = min(rates), max(rates)
        print(f"scaling {t0}→{t1} threads: ×{rates[t1] / rates[t0]:.2f}")
    assert np.array_equal(out.steps[: len(g)], gsteps), "the specialised kernel and the run loop disagree"
    wall, cpu = _timed(lambda: simulate_batch(ics), args.repeat)
    _line(f"simulate_batch, {numba.config.NUMBA_NUM_THREADS} threads", m, out["steps"].sum(), wall, cpu,
          numba.config.NUMBA_NUM_THREADS)
    print(f"mean steps per throw: {out['steps'].mean():.1f}; threading layer {numba.threading_layer()}")


if __name__ == "__main__":
    main()
