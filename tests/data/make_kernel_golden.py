"""Regenerate tests/data/kernel_golden_2000.npz (ONLY with a kernel known to be right).

The golden file freezes the summary results of the simulator kernel as it was
before the performance work (issue 3): 2000 ICs on the seed slice with x, y
uniform in [0, 20] drawn by ``np.random.default_rng(1)``.  It was computed with
the original general loop (``run_roll`` through ``simulate``, one IC at a time).
"""

from pathlib import Path

import numpy as np

from dicetrace.ics import seed_slice
from dicetrace.simulate import STATUS_NAMES, simulate

N = 2000


def golden_points():
    rng = np.random.default_rng(1)
    xy = rng.uniform(0.0, 20.0, size=(N, 2))
    return xy[:, 0].copy(), xy[:, 1].copy()


def main():
    x, y = golden_points()
    ics = seed_slice(x, y)
    codes = {v: k for k, v in STATUS_NAMES.items()}
    status = np.zeros(N, np.int8)
    steps = np.zeros(N, np.int64)
    outcome = np.zeros(N, np.int8)
    offs = np.zeros(N + 1, np.int64)
    sets, set_steps = [], []
    for i in range(N):
        r = simulate(ics[i])
        status[i] = codes[r.status]
        steps[i] = r.steps
        outcome[i] = r.outcome
        sets.append(r.contact_sets)
        set_steps.append(r.contact_steps)
        offs[i + 1] = offs[i] + len(r.contact_sets)
    out = Path(__file__).with_name("kernel_golden_2000.npz")
    np.savez_compressed(
        out, x=x, y=y, ics=ics, status=status, steps=steps, outcome=outcome,
        set_offsets=offs, sets=np.concatenate(sets), set_steps=np.concatenate(set_steps),
    )
    print(f"wrote {out}: {int(steps.sum())} steps, statuses {np.bincount(status)}")


if __name__ == "__main__":
    main()
