"""What recording exact contact events costs: ``simulate_batch(..., record=Record.events_only())`` against the
same batch without.

Runs the same random ``physical`` throws (``contact-tsit5``, its default tolerance schedule) through the batch
kernel with and without events on one thread, interleaved, best of ``--repeat``, and prints the process CPU time
per throw of each and their ratio, with the mean number of contact sets each records (events find the contacts
shorter than an output step, which sampling misses).  The two runs are the same integration bit for bit
(docs/model.md §8.1: the events are read off beside it); the ratio is of CPU time per throw.

Usage: ``python benchmarks/bench_events.py [--n 200] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from dicetrace.params import make_config
from dicetrace.simulate import Record, simulate_batch


def _cpu(ics, cfg, events: bool):
    t0 = time.process_time()
    b = simulate_batch(ics, config=cfg, record=Record.events_only() if events else None, threads=1)
    return time.process_time() - t0, b


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=200, help="throws (default 200)")
    ap.add_argument("--repeat", type=int, default=3, help="interleaved repeats, the best kept (default 3)")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(2026)
    ics = rng.normal(size=(args.n, 6)) * [60.0, 60.0, 20.0, 4000.0, 4000.0, 4000.0]
    cfg = make_config("physical")
    for events in (False, True):  # compile or load, outside the timing
        simulate_batch(ics[:17], config=cfg, record=Record.events_only() if events else None, threads=1)
    best = {False: np.inf, True: np.inf}
    runs = {}
    for _ in range(args.repeat):
        for events in (False, True):
            t, b = _cpu(ics, cfg, events)
            best[events] = min(best[events], t)
            runs[events] = b
    n = len(ics)
    for events in (False, True):
        b = runs[events]
        print(f"{'events' if events else 'sampled':8s} {1e3 * best[events] / n:8.3f} ms CPU per throw, "
              f"{np.mean(np.diff(b.set_offsets)):6.1f} contact sets per throw, {int(b.steps.sum()):,} steps in all")
    print(f"events / sampled, CPU per throw: {best[True] / best[False]:.3f} (one thread, best of {args.repeat})")


if __name__ == "__main__":
    main()
