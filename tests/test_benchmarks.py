"""The benchmark scripts that edit the kernels' source still find what they edit, and the GPU benchmark runs.

``benchmarks/bench_cost_split.py`` measures each part of ``contact-tsit5`` by a
variant of the driver with that part done twice, and
``benchmarks/bench_step_limits.py`` counts what limits its sub-steps with
lines added to the driver; both edit the source of the driver's factory
(``contact_driver.make_drive``).  When the driver changes, an edited line
can vanish and the script stops with a message: building the variants (no
compiling) is enough to catch that here.

``benchmarks/bench_gpu.py`` runs under numba-cuda's simulator at its
``--quick`` sizes (its figures meaningless there, its agreement lines real:
the simulator's seed path is the CPU's bit for bit), and without a GPU it
says why in one line and exits 2.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name: str):
    """The benchmark script ``name`` as a module (benchmarks/ on the path, as when it runs)."""
    if str(BENCHMARKS) not in sys.path:
        sys.path.insert(0, str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_cost_split_variants_build():
    table = _load("bench_cost_split").variants()
    assert list(table)[0] == "plain"
    assert {"substep", "stages", "error", "end forces", "cut test", "interpolation", "step-end forces",
            "flight piece", "impact search"} <= set(table)
    for name, (factory, over) in table.items():
        assert callable(factory), name
        if name in ("cut test", "interpolation", "step-end forces", "end forces", "flight piece", "impact search"):
            # an edited copy of the driver's factory, not the factory itself
            assert factory.__name__.startswith("make_drive_"), name
            assert not over, name
        else:
            assert factory.__name__ == "make_drive", name
    # the method's functions swapped in are the ones the driver reads
    assert set(table["substep"][1]) == set(table["stages"][1]) == {"substep"}
    assert set(table["error"][1]) == {"error"}


def test_step_limits_counters_build():
    mod = _load("bench_step_limits")
    factory = mod.instrumented_drive()
    assert factory.__name__ == "make_drive_limits"
    # every counter the script writes lies inside the field it adds to the work record
    rows, cols = mod.COUNTED.fields["limits"][0].shape
    assert max(mod.ROW_LAM + 2, mod.ROW_OMEGA + 2, mod.ROW_REJECTED, mod.ROW_ACCEPTED) < rows
    assert len(mod.CONTEXTS) <= cols and len(mod.LAM_EDGES) + 1 <= cols and len(mod.OMEGA_EDGES) + 1 <= cols
    # which holds every field of the scheme's work record, as it is (same type and offset)
    W = mod.counted_work()
    for name in mod.WORK.names:
        assert W.dtype.fields[name][:2] == mod.WORK.fields[name][:2], name
    assert not W[0]["limits"].any()
    assert mod._ranges((0.1, 0.3)) == ["≤ 0.1", "0.1–0.3", "> 0.3"]


# -- bench_gpu.py --------------------------------------------------------------------------------------


def _bench_gpu(*args: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BENCHMARKS / "bench_gpu.py"), *args], capture_output=True, text=True,
                          timeout=1200, env={**os.environ, **env})


AGREEMENT_LINES = ("outcomes equal", "steps equal", "contact sequences equal", "status equal")


@pytest.mark.slow
@pytest.mark.long
def test_gpu_bench_runs_on_the_simulator_and_prints_the_agreement(tmp_path):
    written = tmp_path / "gpu.json"
    res = _bench_gpu("--quick", "--skip-scan", "--write", str(written),
                     env={"NUMBA_ENABLE_CUDASIM": "1", "NUMBA_DISABLE_JIT": "1"})
    assert res.returncode == 0, res.stderr[-3000:]
    # --write: what was printed, as numbers, with the machine it ran on
    found = json.loads(written.read_text())
    assert found["simulator"] is True and found["machine"]["gpu"] == "cuda: numba-cuda simulator"
    assert list(found["presets"]) == ["seed", "physical"] and "finished" in found
    for fig in found["presets"].values():
        assert fig["agreement"] == {name: [8, 8] for name in AGREEMENT_LINES}
        assert fig["gpu"]["n"] == fig["cpu"]["n"] == 8 and fig["gpu"]["throws_per_s"] > 0
        assert fig["gpu_one_stream"]["results_identical"] is True
        assert f"{fig['gpu']['throws_per_s']:>12,.0f} throws/s" in res.stdout
    out = res.stdout
    assert "GPU cuda: numba-cuda simulator" in out and "meaningless" in out
    blocks = out.split("\n== ")[1:]
    assert [b.split(" ==")[0] for b in blocks] == ["seed", "physical"]
    for block in blocks:
        preset = block.split(" ==")[0]
        lines = block.splitlines()
        assert any("throws/s" in ln and ln.strip().startswith("GPU") for ln in lines), block
        assert any("throws/s" in ln and ln.strip().startswith("CPU") for ln in lines), block
        got = {}
        for name in AGREEMENT_LINES:
            line = next(ln for ln in lines if ln.strip().startswith(name))
            got[name] = line.split("(")[1].rstrip(")")  # "k of n"
        assert all(v.endswith(" of 8") for v in got.values()), got
        assert set(got.values()) == {"8 of 8"}, got  # on the simulator every preset is the CPU's, bit for bit
        assert any("chaos floor, CPU vs CPU from the ICs nudged by 1e-15" in ln for ln in lines), block
        assert any(ln.strip().startswith(f"{preset} within its chaos floor") or
                   ln.strip().startswith(f"{preset} ABOVE its chaos floor") for ln in lines), block
    assert "scan: skipped (--skip-scan)" in out


@pytest.mark.slow  # a second or more (a fit, a subprocess): the quick loop skips it, CI runs it
def test_gpu_bench_without_a_gpu_says_why_in_one_line_and_exits_2():
    res = _bench_gpu("--quick", env={"NUMBA_ENABLE_CUDASIM": "0", "CUDA_VISIBLE_DEVICES": ""})
    assert res.returncode == 2, (res.stdout, res.stderr)
    assert res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench_gpu: no GPU to benchmark: "), res.stderr


@pytest.mark.parametrize("args, names", [
    (("--presets", "seed,nope"), ("--presets", "nope")),
    (("--n", "0"), ("--n",)),
    (("--rate-n", "many"), ("--rate-n",)),
    (("--scan-preset", "moon"), ("--scan-preset", "moon")),
    (("--scan-devices", "cpu,tpu"), ("--scan-devices", "tpu")),
])
def test_gpu_bench_bad_options_are_one_line_exit_2(args, names):
    res = _bench_gpu(*args, env={"NUMBA_ENABLE_CUDASIM": "0", "CUDA_VISIBLE_DEVICES": ""})
    assert res.returncode == 2 and res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bench_gpu: error: "), res.stderr
    assert all(n in lines[0] for n in names), lines[0]


def _result(outcome, steps, status, sequences):
    offsets = np.concatenate([[0], np.cumsum([len(q) for q in sequences])])
    sets = np.array([s for q in sequences for s in q], dtype=np.uint8)
    return SimpleNamespace(outcome=np.array(outcome), steps=np.array(steps), status_code=np.array(status),
                           set_offsets=offsets, sets=sets)


def test_gpu_bench_agreement_counts_each_kind_of_difference():
    mod = _load("bench_gpu")
    a = _result([1, 2, 3, 4, 5], [10, 20, 30, 40, 50], [0, 0, 0, 0, 0], [[0, 1], [0, 2, 3], [0], [0, 4], [0, 5]])
    b = _result([1, 2, 6, 4, 5], [10, 21, 30, 40, 50], [0, 0, 0, 0, 1], [[0, 1], [0, 2, 3], [0], [0, 4, 4], [0, 6]])
    got = {k: v.tolist() for k, v in mod.agreement(a, b, 5).items()}
    assert got == {
        "outcomes equal": [True, True, False, True, True],
        "steps equal": [True, False, True, True, True],
        "contact sequences equal": [True, True, True, False, False],  # a longer sequence, then another set
        "status equal": [True, True, True, True, False],
    }
    # the first n throws only (the GPU's run may hold more ICs than the agreement's)
    assert mod.agreement(a, b, 2)["contact sequences equal"].tolist() == [True, True]


def test_gpu_bench_nudge_is_a_few_ulps_and_the_floor_verdict():
    mod = _load("bench_gpu")
    ics = np.array(mod.slice_ics(50, 3))
    moved = mod.nudged(ics, 4)
    rel = np.abs(moved - ics) / np.abs(ics)
    assert np.all(rel <= 1.5e-15) and np.mean(rel > 0.5e-15) > 0.9  # every component moved, by about 1e-15
    assert np.array_equal(moved, mod.nudged(ics, 4))
    assert mod.within_floor(0, 0) and mod.within_floor(12, 10) and mod.within_floor(3, 10)
    assert not mod.within_floor(40, 10)


@pytest.mark.slow
def test_explore_bench_writes_its_figures_for_the_device_it_ran_on(tmp_path):
    """bench_explore.py --write: the passes of both windows, the batch kernel alone, the device and the machine."""
    out = tmp_path / "explore.json"
    r = subprocess.run([sys.executable, str(BENCHMARKS / "bench_explore.py"), "--res", "16", "--write", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    got = json.loads(out.read_text())
    assert got["device"] == "cpu" and got["res"] == 16 and got["preset"] == "seed"
    for w in ("red-sea", "red-sea-2"):
        t = got["windows"][w]
        assert 0 < t["first_image_s"] <= t["coarse_s"] <= t["first_strip_s"] <= t["refined_s"]
    assert got["batch_alone_s"] > 0 and got["machine"]["cores"] >= 1


@pytest.mark.parametrize("ndim, connectivity, k", [(2, "face", 6), (2, "full", 6), (3, "face", 4), (2, "face", 300)])
def test_bench_cells_compares_two_routes_to_the_same_cells(ndim, connectivity, k):
    """bench_cells.py times scipy's ndimage.label label by label against label_cells' one scikit-image pass: both
    give the same cells, numbered alike, so the timing compares like with like."""
    from dicetrace.analysis import label_cells

    bench = _load("bench_cells")
    g = bench._blocks(60 if ndim == 2 else 16, k, ndim, np.random.default_rng(k))
    ids, n = label_cells(g, connectivity=connectivity)
    ids_sp, n_sp = bench.scipy_label_cells(g, connectivity)
    assert n > 10 and n_sp == n and np.array_equal(ids_sp, ids)
