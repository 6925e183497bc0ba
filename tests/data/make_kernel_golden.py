"""How tests/data/kernel_golden_2000.npz was made (do not regenerate it casually).

The golden file freezes the summary results of the simulator kernel as it was
before the performance work of issue 3: 2000 ICs on the seed slice with x, y
uniform in [0, 20] drawn by ``np.random.default_rng(1)``, computed one IC at a
time by the original loop (then and today ``run_roll``, the tracing loop).
Its point is to catch a change of the kernel, so re-running this script with a
changed kernel defeats it.
"""

from pathlib import Path

import numpy as np

from dicetrace.core.kernels import roll_out, run_roll
from dicetrace.ics import seed_slice
from dicetrace.params import make_config

N = 2000


def golden_points():
    rng = np.random.default_rng(1)
    xy = rng.uniform(0.0, 20.0, size=(N, 2))
    return xy[:, 0].copy(), xy[:, 1].copy()


def main():
    x, y = golden_points()
    ics = seed_slice(x, y)
    cfg = make_config("seed")
    kp, off0 = cfg.kernel_params(), cfg.initial_offsets()
    status = np.zeros(N, np.int8)
    steps = np.zeros(N, np.int64)
    outcome = np.zeros(N, np.int8)
    offs = np.zeros(N + 1, np.int64)
    sets, set_steps = [], []
    buf, buf_steps = np.zeros(4096, np.uint8), np.zeros(4096, np.int32)
    for i in range(N):
        st, n, o, ns = run_roll(ics[i], off0, kp, 0, roll_out(buf, buf_steps))
        status[i], steps[i], outcome[i] = st, n, o
        sets.append(buf[:ns].copy())
        set_steps.append(buf_steps[:ns].copy())
        offs[i + 1] = offs[i] + ns
    out = Path(__file__).with_name("kernel_golden_2000.new.npz")
    np.savez_compressed(
        out, x=x, y=y, ics=ics, status=status, steps=steps, outcome=outcome,
        set_offsets=offs, sets=np.concatenate(sets), set_steps=np.concatenate(set_steps),
    )
    print(f"wrote {out} (compare it with the frozen file; rename only on purpose): "
          f"{int(steps.sum())} steps, statuses {np.bincount(status)}")


if __name__ == "__main__":
    main()
