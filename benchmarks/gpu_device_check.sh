#!/usr/bin/env bash
# The GPU check, in one run, on a machine with a CUDA GPU: the tests marked gpu (tests/core/test_gpu.py), then
# benchmarks/bench_gpu.py at the sizes the GPU issue asks for (10^5 ICs of agreement per preset, 10^6 for the
# GPU's rate, the 1000 x 1000 seed scan on each device; on the GPU with one CUDA stream and with two, which gives
# the gain of overlapping a chunk's transfers and host work with the next chunk's kernel; the 1000 x 1000 physical
# scan on the GPU, loading its kernel and again from a warm cache), and a 300 x 300 GPU scan
# on two Dask workers against the same scan in one process (their rows must be identical), and the explorer's
# 256 x 256 view of `physical` (its map worker, without the web server) on the GPU and on the CPU.
#
# For a machine with numba-cuda, numpy, scipy, pyarrow and pandas and nothing else of dicetrace's dependencies
# (no rerun-sdk, no internet): it runs the working tree as it is (PYTHONPATH=src, nothing installed), from the
# repository root.  Sized for about 6 minutes on an H200 beside a 16-core CPU, at most 9 min 40 s (the sum of
# the parts' limits, 580 s), where the numba cache starts cold (the CPU's kernels compile in the tests' run and load
# from the cache after); each part has a time limit, and
# the benchmark prints as it goes, so a part cut short still leaves what it measured.  dicetrace scan needs
# typer as well: without it bench_gpu.py says the scan is not available.
#
# Output: on standard output and, where OUT is set, in $OUT/gpu_check.txt, with the benchmark's figures as JSON in
# $OUT/bench_gpu_seed.json, $OUT/bench_gpu_physical.json (bench_gpu.py --write), $OUT/scan_dask_gpu.json and
# $OUT/explore_gpu.json: the results files the README's GPU figures are to be quoted from (copy them to
# benchmarks/results/).
#
# Usage: bash benchmarks/gpu_device_check.sh    (PYTHON=... to choose the interpreter)
set -u
cd "$(dirname "$0")/.."
export PYTHONPATH="src${PYTHONPATH:+:$PYTHONPATH}"
PY="${PYTHON:-$(command -v python3 || command -v python)}"
LOG=/dev/null
if [ -n "${OUT:-}" ]; then
    mkdir -p "$OUT"
    LOG="$OUT/gpu_check.txt"
    : > "$LOG"
fi

say() { echo "$@" | tee -a "$LOG"; }
part() {  # part LIMIT_S TITLE COMMAND...: one timed part, its output kept, its exit status said
    local limit=$1 title=$2
    shift 2
    say ""
    say "### $title ($(date -u +%H:%M:%S), at most ${limit} s)"
    local t0=$SECONDS
    timeout "$limit" "$@" 2>&1 | tee -a "$LOG"
    local rc=${PIPESTATUS[0]}
    say "### exit $rc after $((SECONDS - t0)) s$([ "$rc" = 124 ] && echo ' (time limit: cut short)')"
}

say "### machine"
(nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>&1 || true) | tee -a "$LOG"
"$PY" -c 'import sys, numpy, numba; print("python", sys.version.split()[0], "numpy", numpy.__version__, "numba", numba.__version__)' 2>&1 | tee -a "$LOG"
say "git: $(git rev-parse --short HEAD 2>/dev/null || echo 'not a git checkout') $(git status --short 2>/dev/null | wc -l | tr -d ' ') changed files"

if "$PY" -c 'import pytest' 2>/dev/null; then
    part 170 "tests marked gpu" "$PY" -m pytest -q -m gpu tests/core/test_gpu.py -p no:cacheprovider
else
    say "### tests marked gpu: not run (pytest is not installed)"
fi
# seed first, with the scan (quick; the GPU's scan with one stream and with two: the overlap); then physical, with
# its 1000 x 1000 scan on the GPU only (the CPU's would take about 30 s of 16 cores; its rate is measured above)
W_SEED=() W_PHYSICAL=()
if [ -n "${OUT:-}" ]; then
    W_SEED=(--write "$OUT/bench_gpu_seed.json") W_PHYSICAL=(--write "$OUT/bench_gpu_physical.json")
fi
part 115 "bench_gpu: seed, and the scan" "$PY" benchmarks/bench_gpu.py --presets seed --n 100000 --rate-n 1000000 --repeat 3 \
    ${W_SEED[@]+"${W_SEED[@]}"}
part 165 "bench_gpu: physical, and its scan on the GPU" "$PY" benchmarks/bench_gpu.py --presets physical --n 100000 \
    --rate-n 1000000 --scan-preset physical --scan-devices cuda --no-scan-overlap ${W_PHYSICAL[@]+"${W_PHYSICAL[@]}"}
# two Dask workers on the GPU(s) (sharing one where there is one): the rows of the one-process GPU scan
if "$PY" -c 'import dask.distributed, typer' 2>/dev/null; then
    part 70 "scan on Dask, --device cuda, 2 workers, against one process" "$PY" - <<'PYEOF'
import json, os, subprocess, sys, tempfile, time
from pathlib import Path
from dicetrace.scan import read_scan
tmp = Path(tempfile.mkdtemp(prefix="gpu_check_dask_"))
base = [sys.executable, "-m", "dicetrace.cli", "scan", "--window", "0,20,0,20", "--res", "300", "--chunk", "16384",
        "--device", "cuda", "--yes", "-q"]
walls = {}
for name, extra in (("one", []), ("dask", ["--dask", "--workers", "2"])):
    t = time.perf_counter()
    r = subprocess.run([*base, "--out", str(tmp / name), *extra], capture_output=True, text=True)
    walls[name] = time.perf_counter() - t
    print(f"{name}: exit {r.returncode} in {walls[name]:.1f} s {r.stderr.strip()[-300:]}", flush=True)
a, b = read_scan(tmp / "one"), read_scan(tmp / "dask")
cols = ["ic_id", "outcome", "status", "steps", "contact_sequence"]
same = len(a) == len(b) == 90000 and a[cols].equals(b[cols])
print("rows identical to the one-process GPU scan:", same)
if os.environ.get("OUT"):
    Path(os.environ["OUT"], "scan_dask_gpu.json").write_text(json.dumps(
        {"scan": " ".join(base[3:]), "wall_s": walls, "rows_identical": bool(same)}, indent=1) + "\n")
PYEOF
else
    say "### scan on Dask: not run (dask.distributed or typer is not installed)"
fi
# the live converged explorer: a 256 x 256 view of physical, as the explorer's map worker computes it
part 60 "explorer: a 256 x 256 view of physical, GPU and CPU" "$PY" - <<'PYEOF'
import json, os, time
from pathlib import Path
from dicetrace.explore import View, Worker
found = {"view": "red-sea, 256 x 256, physical", "cpu_cores": os.cpu_count(), "refined_s": {}}
for device in ("cuda", "cpu"):
    w = Worker(device=device)
    try:
        w.submit_map(View(window=((1.0, 1.1), (3.5, 3.6)), res=(16, 16), preset="physical"), client="warm").result()
        t = time.perf_counter()
        m = w.submit_map(View(window="red-sea", res=(256, 256), preset="physical"), client="bench").result()
        wall = time.perf_counter() - t
        print(f"{device}: a 256 x 256 red-sea view of physical in {wall:.2f} s "
              f"({m.outcome.size} throws; {os.cpu_count()} CPU cores)", flush=True)
        found["refined_s"][device] = wall
        if os.environ.get("OUT"):
            Path(os.environ["OUT"], "explore_gpu.json").write_text(json.dumps(found, indent=1) + "\n")
    finally:
        w.shutdown()
PYEOF
say ""
say "### done after ${SECONDS} s"
