"""Cost per throw of the contact-aware integrators, against the seed path.

On the accuracy study's ICs (300 seeded points of the zoom-out window; L
negated for ``physical``), one numba thread, best of ``--repeat`` runs of
``simulate_batch``: CPU ms per throw for

* ``seed`` with the program's semi-implicit Euler at dt = 1 ms (the seed's cost),
* ``contact-substep`` at dt = 1 ms and 2 ms (8 fixed sub-steps per dt in contact),
* ``contact-adaptive`` at dt = 1 ms and tol = 1e-4 … 1e-7,

for both presets.  Outcome agreement at these settings is the accuracy
study's (``analysis/accuracy/summary.md``); this script measures cost only,
more steadily (best of several runs).

Usage: ``python benchmarks/bench_integrators.py [--n 300] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import time

import numba
import numpy as np

from dicetrace.studies.accuracy import sample_ics
from dicetrace.params import make_config
from dicetrace.simulate import simulate_batch

RUNS = [
    ("semi-implicit-euler", 1e-3, None),
    ("contact-substep", 2e-3, None),
    ("contact-substep", 1e-3, None),
    ("contact-adaptive", 1e-3, 1e-4),
    ("contact-adaptive", 1e-3, 1e-5),
    ("contact-adaptive", 1e-3, 1e-6),
    ("contact-adaptive", 1e-3, 1e-7),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    numba.set_num_threads(1)
    ics = sample_ics(n=args.n)
    print(f"{args.n} zoom-out ICs, 1 thread, CPU ms per throw (best of {args.repeat})")
    for preset in ("seed", "physical"):
        x = ics.copy()
        if preset == "physical":
            x[:, 3:] *= -1.0
        for integ, dt, tol in RUNS:
            cfg = make_config(preset, integrator=integ, dt_s=dt, t_max_s=20.0, tol=tol)
            simulate_batch(x[:2], config=cfg)  # compile / load the cache
            best = np.inf
            for _ in range(args.repeat):
                t0 = time.process_time()
                r = simulate_batch(x, config=cfg)
                best = min(best, time.process_time() - t0)
            label = f"{integ} dt={dt:g}" + ("" if tol is None else f" tol={tol:g}")
            bad = int(np.sum(r.status != "settled"))
            print(f"  {preset:<9} {label:<38} {best / args.n * 1e3:8.3f} ms/throw   unsettled {bad}")


if __name__ == "__main__":
    main()
