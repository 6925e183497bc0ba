"""The fast summary kernel (core/fast.py) against the general loop and a frozen golden set.

``run_summary`` (the summary loop ``run_batch`` runs per IC) sends the summary path of semi-implicit Euler with the
point-mass stop test (the ``seed`` preset) to ``fast.roll_summary_sie``;
the tracing loop (``run_roll``, the run loop with its trace code) is the original loop it must reproduce bit for bit
(status, steps, outcome, contact sets and their steps).  The golden file
``tests/data/kernel_golden_2000.npz`` froze the results of the original
kernel (before any optimisation) on 2000 seed-slice ICs, x, y uniform in
[0, 20] from ``np.random.default_rng(1)``; ``tests/data/make_kernel_golden.py``
made it.  Never regenerate it with a changed kernel.
"""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
import pandas as pd
import pytest

from dicetrace.core.fast import mirror_symmetric, roll_summary_sie
from dicetrace.core.kernels import SLICE_STEPS, batch_out, roll_out, run_batch, run_summary
from dicetrace.core.kernels import run_roll as _run_roll
from dicetrace.core.loop import ENERGY_COLS, FORCE_COLS, STATE_COLS
from dicetrace.ics import seed_slice
from dicetrace.params import make_config
from dicetrace.simulate import Record, simulate, simulate_batch

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "kernel_golden_2000.npz"
EMPTY = (np.zeros((0, STATE_COLS)), np.zeros((0, FORCE_COLS)), np.zeros((0, ENERGY_COLS)))
CAP = 4096


@pytest.fixture(scope="module")
def golden():
    g = np.load(GOLDEN)
    return {k: g[k] for k in g.files}


def _serial(fn, ics, cfg, off0=None, integ=None):
    """(status, steps, outcome, [sets], [set_steps]) of every IC through ``fn`` (run_roll-like)."""
    kp = cfg.kernel_params()
    off0 = cfg.initial_offsets() if off0 is None else off0
    integ = cfg.numerics.integrator_id if integ is None else integ
    out = []
    sets = np.zeros(CAP, np.uint8)
    steps = np.zeros(CAP, np.int32)
    for ic in ics:
        s, n, o, ns = fn(ic, off0, kp, integ, sets, steps, *EMPTY)
        out.append((int(s), int(n), int(o), sets[:ns].copy(), steps[:ns].copy()))
    return out


def _summary(ic, off0, kp, integ, sets, set_steps, *_trace):
    """``run_summary`` with ``run_roll``'s signature (the trace arrays, empty, are dropped)."""
    return run_summary(ic, off0, kp, integ, sets, set_steps)


def run_roll(ic, off0, kp, integ, sets, set_steps, *trace):
    """``kernels.run_roll`` (the tracing loop) on these sets and trace arrays."""
    return _run_roll(ic, off0, kp, integ, roll_out(sets, set_steps, None, *trace))


def _assert_same(a, b):
    assert len(a) == len(b)
    for i, (x, y) in enumerate(zip(a, b)):
        assert x[:3] == y[:3], f"IC {i}: (status, steps, outcome) {x[:3]} != {y[:3]}"
        np.testing.assert_array_equal(x[3], y[3], err_msg=f"IC {i}: contact sets")
        np.testing.assert_array_equal(x[4], y[4], err_msg=f"IC {i}: contact steps")


def test_golden_file_is_the_documented_sample(golden):
    rng = np.random.default_rng(1)
    xy = rng.uniform(0.0, 20.0, size=(2000, 2))
    np.testing.assert_array_equal(golden["x"], xy[:, 0])
    np.testing.assert_array_equal(golden["ics"], seed_slice(xy[:, 0], xy[:, 1]))


def test_batch_matches_golden(golden):
    """The optimised batch path reproduces the pre-optimisation kernel on 2000 ICs."""
    b = simulate_batch(golden["ics"])
    np.testing.assert_array_equal(b.status_code, golden["status"])
    np.testing.assert_array_equal(b.steps, golden["steps"])
    np.testing.assert_array_equal(b.outcome, golden["outcome"])
    np.testing.assert_array_equal(b.set_offsets, golden["set_offsets"])
    np.testing.assert_array_equal(b.sets, golden["sets"])
    np.testing.assert_array_equal(b.set_steps, golden["set_steps"])


def test_serial_fast_path_matches_golden_and_general_loop(golden):
    cfg = make_config("seed")
    ics = golden["ics"][:400]
    fast = _serial(_summary, ics, cfg)
    general = _serial(run_roll, ics, cfg)
    _assert_same(fast, general)
    off = golden["set_offsets"]
    frozen = [
        (int(golden["status"][i]), int(golden["steps"][i]), int(golden["outcome"][i]),
         golden["sets"][off[i]:off[i + 1]], golden["set_steps"][off[i]:off[i + 1]])
        for i in range(len(ics))
    ]
    _assert_same(fast, frozen)


@pytest.mark.parametrize(
    "label, kwargs",
    [
        ("per-node friction", dict(friction="per-node")),
        ("clamped normal force", dict(clamp_normal=True)),
        ("damping 0.01 (the writeup's damping figure)", dict(gamma=0.01)),
        ("low friction", dict(mu=0.3)),
        ("coarser step", dict(dt_s=0.002)),
        ("short time cap", dict(t_max_s=0.3)),
    ],
)
def test_fast_path_matches_general_loop_on_variants(label, kwargs):
    """Parameter variations of the seed preset that the fast path also covers."""
    cfg = make_config("seed", **kwargs)
    rng = np.random.default_rng(7)
    xy = rng.uniform(0.0, 20.0, size=(120, 2))
    ics = seed_slice(xy[:, 0], xy[:, 1])
    fast = _serial(_summary, ics, cfg)
    _assert_same(fast, _serial(run_roll, ics, cfg))
    if "t_max_s" in kwargs:
        assert any(r[0] == 1 for r in fast), "expected some time-capped throws"


def test_fast_path_matches_general_loop_on_special_ics():
    """Grid edges with exact zeros in the IC (x = 0 or y = 0; (0, 0) spins about y only),
    where signed zeros and symmetric contacts could tell the two paths apart."""
    cfg = make_config("seed")
    xs = np.linspace(0.0, 0.1, 11)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    edge = (x == 0) | (y == 0)
    ics = np.concatenate([
        seed_slice(x[edge], y[edge]),
        [[0.0, 0.0, 0.0, 0.0, 100.0, 0.0], [0.0, 0.0, -50.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
         [-0.0, -0.0, 0.0, -0.0, 100.0, -0.0], [30.0, 0.0, 0.0, 0.0, 0.0, 250.0]],
    ])
    _assert_same(_serial(_summary, ics, cfg), _serial(run_roll, ics, cfg))


def test_fast_path_from_a_tilted_start():
    """A rotated initial cube (mirror-symmetric offsets) runs the fast path, same bits."""
    from scipy.spatial.transform import Rotation

    cfg = make_config("seed")
    rot = Rotation.from_rotvec([0.3, -0.7, 0.2]).as_matrix()
    off0 = cfg.initial_offsets(rot)
    assert mirror_symmetric(off0)
    rng = np.random.default_rng(3)
    xy = rng.uniform(0.0, 20.0, size=(100, 2))
    ics = seed_slice(xy[:, 0], xy[:, 1])
    _assert_same(_serial(_summary, ics, cfg, off0), _serial(run_roll, ics, cfg, off0))


def test_non_symmetric_start_falls_back_to_general_loop():
    cfg = make_config("seed")
    off0 = cfg.initial_offsets().copy()
    off0[0, 0] = np.nextafter(off0[0, 0], 0.0)
    assert not mirror_symmetric(off0)
    ics = seed_slice(np.array([1.65, 0.3]), np.array([3.9, 7.1]))
    _assert_same(_serial(_summary, ics, cfg, off0), _serial(run_roll, ics, cfg, off0))


def test_buffer_full_is_reported_identically():
    cfg = make_config("seed")
    kp = cfg.kernel_params()
    off0 = cfg.initial_offsets()
    ic = seed_slice(1.65, 3.9)  # 23 contact sets
    for cap in (1, 5, 23):
        res = []
        for fn in (_summary, run_roll):
            sets = np.zeros(cap, np.uint8)
            steps = np.zeros(cap, np.int32)
            res.append(fn(ic, off0, kp, 0, sets, steps, *EMPTY) + (sets.copy(), steps.copy()))
        for other in res[1:]:
            assert other[:4] == res[0][:4]
            np.testing.assert_array_equal(other[4], res[0][4])
        assert res[0][0] == (4 if cap < 23 else 0)


def test_offsets_stay_mirror_symmetric_along_a_trace(reference_dir):
    """The premise of the fast kernel: node 8-k is node k+1 negated, bitwise, at every step."""
    ref = pd.read_csv(reference_dir / "trace_random_id1.csv")
    ic = ref.loc[0, ["ux", "uy", "uz", "Lx", "Ly", "Lz"]].to_numpy(float)
    off = simulate(ic, record=Record(states=True, energy=False)).trace.node_offsets
    np.testing.assert_array_equal(off[:, ::-1, :], -off)


def test_writeup_points_and_trace_still_match_the_program(reference_dir):
    pts = pd.read_csv(reference_dir / "writeup_points.csv")
    for r in pts.itertuples():
        roll = simulate(seed_slice(r.x, r.y))
        assert (roll.outcome, roll.steps, roll.contact_sequence) == (r.outcome, r.steps, r.contact_sequence)
    ref = pd.read_csv(reference_dir / "trace_redsea_x1.65_y3.9.csv")
    ic = ref.loc[0, ["ux", "uy", "uz", "Lx", "Ly", "Lz"]].to_numpy(float)
    tr = simulate(ic, record=Record(states=True, energy=False)).trace
    ours = np.concatenate([tr.cm_pos, tr.cm_vel, tr.L, tr.node_offsets.reshape(-1, 24)], axis=1)
    want = ref[["cmx", "cmy", "cmz", "ux", "uy", "uz", "Lx", "Ly", "Lz"]
               + [f"X{k}_{a}" for k in range(1, 9) for a in "xyz"]].to_numpy()
    assert ours.shape == want.shape
    np.testing.assert_array_equal(ours[:177], want[:177])
    np.testing.assert_allclose(ours, want, rtol=1e-10, atol=1e-10 * np.abs(want).max())


@pytest.mark.parametrize("threads", [1, 2])
def test_batch_is_thread_and_schedule_invariant(golden, threads):
    cfg = make_config("seed")
    kp = cfg.kernel_params()
    off0 = cfg.initial_offsets()
    ics = golden["ics"][:300]
    m, cap = len(ics), 64
    results = []
    for chunksize in (0, 1, 7):
        arrs = batch_out(m, cap)
        old = numba.get_num_threads()
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        try:
            with numba.parallel_chunksize(chunksize):
                run_batch(ics, off0, kp, 0, cap, arrs)
        finally:
            numba.set_num_threads(old)
        results.append(arrs)
    for other in results[1:]:
        for a, b in zip(results[0], other):
            np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(results[0][1], golden["steps"][:300])


def test_scratch_kernel_is_reentrant():
    """Nothing carries over from one throw to the next."""
    cfg = make_config("seed")
    kp = cfg.kernel_params()
    off0 = cfg.initial_offsets()
    a, b = seed_slice(1.65, 3.9), seed_slice(0.019775, 0.0182)
    sets = np.zeros(256, np.uint8)
    steps = np.zeros(256, np.int32)
    first = roll_summary_sie(b, off0, kp, sets, steps, SLICE_STEPS)
    roll_summary_sie(a, off0, kp, sets, steps, SLICE_STEPS)
    assert roll_summary_sie(b, off0, kp, sets, steps, SLICE_STEPS) == first


@pytest.mark.parametrize("integrator", ["semi-implicit-euler", "verlet"], ids=["fast kernel", "summary loop"])
def test_an_overflowing_start_fails_at_the_same_step_on_every_path(integrator):
    """|U| = 1e300: the stop energy overflows at the first step.  The summary loop's free-flight
    energy bound is then NaN and must not skip the exact (infinite) energy: every path reports
    non_finite at step 1 (the seed's point-mass stop test with Verlet has no specialised kernel,
    so it runs the summary loop)."""
    from dicetrace.params import INTEGRATORS

    cfg = make_config("seed", integrator=integrator)
    kp = cfg.kernel_params()
    integ = INTEGRATORS[integrator].kernel_id
    ic = np.array([1e300, 0, 0, 0, 0, 0])
    res = [fn(ic, cfg.initial_offsets(), kp, integ, np.zeros(8, np.uint8), np.zeros(8, np.int32), *EMPTY)
           for fn in (_summary, run_roll)]
    assert [tuple(map(int, r)) for r in res] == [(2, 1, -1, 1)] * 2  # NON_FINITE, 1 step, no outcome, 1 set
