"""Throughput and memory of ``dicetrace.scan`` on the seed slice x, y ∈ [0, 20].

Scans a grid of the seed slice (default 150 × 150 = 22,500 ICs) with 1 and
2 threads, in memory and into a Parquet folder (chunks, metadata, atomic
renames: the whole ``dicetrace scan`` path), and prints throws/s and ns per
simulated step.  Then checks that memory does not grow with the number of
ICs: peak Python/numpy allocations (tracemalloc) and the Arrow pool's peak
during folder scans of 1× and 4× as many ICs.

Usage: ``python benchmarks/bench_scan.py [--res 150] [--threads 1,2] [--no-memory]``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
import tracemalloc
from pathlib import Path

import numba
import pyarrow as pa

from dicetrace.ics import Grid
from dicetrace.scan import read_scan_table, scan

WINDOW = ((0.0, 20.0), (0.0, 20.0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=150, help="grid points per axis (default 150: 22,500 ICs)")
    ap.add_argument("--threads", default="1,2", help="thread counts (default 1,2)")
    ap.add_argument("--chunk", type=int, default=8192)
    ap.add_argument("--no-memory", action="store_true", help="skip the memory check")
    args = ap.parse_args()

    grid = Grid("seed", WINDOW, args.res)
    print(f"scan of the seed slice [0, 20]², {args.res}×{args.res} = {grid.size:,} ICs, chunk {args.chunk}; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    scan(Grid("seed", WINDOW, 4), chunk=8)  # compile / load caches
    tmp = Path(tempfile.mkdtemp(prefix="dicetrace-bench-"))
    try:
        rates = {}
        for t in [min(int(v), numba.config.NUMBA_NUM_THREADS) for v in args.threads.split(",")]:
            w, c = time.perf_counter(), time.process_time()
            table = scan(grid, chunk=args.chunk, threads=t)
            wall, cpu = time.perf_counter() - w, time.process_time() - c
            steps = int(pa.compute.sum(table["steps"]).as_py())
            rates[t] = grid.size / wall
            print(f"in memory, {t} thread(s):  {grid.size / wall:>9,.0f} throws/s {wall * 1e9 / steps:>6.1f} ns/step"
                  f"  | {grid.size / cpu:>8,.0f} throws per CPU-second")
            out = tmp / f"t{t}"
            w = time.perf_counter()
            rep = scan(grid, out, chunk=args.chunk, threads=t)
            wall = time.perf_counter() - w
            assert rep.complete
            print(f"to Parquet, {t} thread(s): {grid.size / wall:>9,.0f} throws/s {wall * 1e9 / steps:>6.1f} ns/step"
                  f"  ({sum(p.stat().st_size for p in out.iterdir()) / grid.size:.0f} bytes/IC on disk)")
            back = read_scan_table(out)
            assert back["outcome"].equals(table["outcome"]) and back["steps"].equals(table["steps"])
        if len(rates) > 1:
            a, b = min(rates), max(rates)
            print(f"scaling {a}→{b} threads: ×{rates[b] / rates[a]:.2f}; mean steps per throw {steps / grid.size:.1f}")
        if not args.no_memory:
            small = Grid("seed", WINDOW, 60)
            big = Grid("seed", WINDOW, 120)
            peaks = []
            for g in (small, big):
                pool = pa.default_memory_pool()
                tracemalloc.start()
                scan(g, tmp / f"mem{g.res[0]}", chunk=1024)
                _, peak = tracemalloc.get_traced_memory()
                tracemalloc.stop()
                peaks.append((g.size, peak, pool.max_memory()))
            for n, peak, arrow in peaks:
                print(f"memory, {n:>6,} ICs to Parquet (chunk 1024): peak numpy/Python {peak / 2**20:6.1f} MiB, "
                      f"Arrow pool peak {arrow / 2**20:6.1f} MiB (process-wide, monotone)")
            print(f"ICs ×{peaks[1][0] / peaks[0][0]:.0f} → peak numpy/Python memory ×{peaks[1][1] / peaks[0][1]:.2f}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
