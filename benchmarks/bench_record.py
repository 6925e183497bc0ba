"""Time a 3000-step recording: the traced simulation and the .rrd writer, separately.

Usage::

    .venv/bin/python benchmarks/bench_record.py [--repeat 5] [--out DIR]

The IC is the seed slice at (x, y) = (91, 71.5), a long throw (4598 steps to
rest); the time cap of 3.0 s stops it at exactly 3000 steps.  The full throw
is timed too.  Each figure is the median of ``--repeat`` runs after one
warm-up (numba compilation and the first rerun import are not counted).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from dicetrace.ics import seed_slice
from dicetrace.simulate import Record, simulate
from dicetrace.sinks.parquet import write_tables
from dicetrace.sinks.rerun import write_rrd

XY = (91.0, 71.5)


def median_time(fn, repeat: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bench(t_max_s: float | None, repeat: int, out: Path) -> None:
    ic = seed_slice(*XY)
    rec = Record(states=True, energy=True)
    kw = {} if t_max_s is None else {"t_max_s": t_max_s}
    roll = simulate(ic, record=rec, **kw)
    t_sim = median_time(lambda: simulate(ic, record=rec, **kw), repeat)
    t_sum = median_time(lambda: simulate(ic, **kw), repeat)
    rrd = out / f"bench_{roll.steps}.rrd"
    t_rrd = median_time(lambda: write_rrd(roll, rrd), repeat)
    pq_dir = out / f"pq_{roll.steps}"
    t_pq = median_time(lambda: write_tables(pq_dir, roll), repeat)
    pq_size = sum(p.stat().st_size for p in pq_dir.iterdir())
    print(
        f"{roll.steps:5d} steps ({roll.status:8s}): simulate summary {t_sum * 1e3:7.2f} ms | "
        f"simulate + trace {t_sim * 1e3:7.2f} ms | write_rrd {t_rrd * 1e3:7.2f} ms, "
        f"{rrd.stat().st_size / 1024:7.0f} KiB | write_tables {t_pq * 1e3:7.2f} ms, {pq_size / 1024:6.0f} KiB"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", type=Path, default=None, help="folder for the files (default: a temporary one)")
    args = ap.parse_args()
    print(f"seed slice at x={XY[0]}, y={XY[1]}; median of {args.repeat} runs")
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        bench(3.0, args.repeat, out)
        bench(None, args.repeat, out)


if __name__ == "__main__":
    main()
