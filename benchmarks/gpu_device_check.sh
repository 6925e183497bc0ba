#!/usr/bin/env bash
# The GPU check, in one run, on a machine with a CUDA GPU: the tests marked gpu (tests/core/test_gpu.py), then
# benchmarks/bench_gpu.py at the sizes the GPU issue asks for (10^5 ICs of agreement per preset, 10^6 for the
# GPU's rate, the 1000 x 1000 scan on each device).
#
# For a machine with numba-cuda, numpy, scipy, pyarrow and pandas and nothing else of dicetrace's dependencies
# (no rerun-sdk, no internet): it runs the working tree as it is (PYTHONPATH=src, nothing installed), from the
# repository root.  Sized for about 6 minutes on an H200 beside a 16-core CPU, where the numba cache starts cold
# (the CPU's kernels compile in the tests' run and load from the cache after); each part has a time limit, and
# the benchmark prints as it goes, so a part cut short still leaves what it measured.  dicetrace scan needs
# typer as well: without it bench_gpu.py says the scan is not available.
#
# Output: on standard output and, where OUT is set, in $OUT/gpu_check.txt.
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
    part 200 "tests marked gpu" "$PY" -m pytest -q -m gpu tests/core/test_gpu.py -p no:cacheprovider
else
    say "### tests marked gpu: not run (pytest is not installed)"
fi
# seed first, with the scan (quick); then physical, the long one
part 120 "bench_gpu: seed, and the scan" "$PY" benchmarks/bench_gpu.py --presets seed --n 100000 --rate-n 1000000 --repeat 3
part 240 "bench_gpu: physical" "$PY" benchmarks/bench_gpu.py --presets physical --n 100000 --rate-n 1000000 --skip-scan
say ""
say "### done after ${SECONDS} s"
