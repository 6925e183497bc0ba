"""The GPU backend against the CPU, in one run: throughput, agreement, the chaos floor and a scan's wall time.

For each preset (``--presets``, default ``seed,physical``: the seed kernel
and ``physical``'s default, contact-tsit5 through the general kernel) it
prints

* the first call's time on each device (``simulate_batch`` on a few ICs:
  on the GPU it compiles the kernel, or loads it from numba-cuda's disk
  cache after a first run of the same kernel sources; on the CPU it loads
  the kernels from numba's cache, or compiles them where the cache is cold);
* throws/s through ``simulate_batch(ics, config=preset, device="cuda")`` on
  ``--rate-n`` ICs, and through ``device="cpu"`` on all numba threads on
  the ``--n`` agreement ICs, both after that first call (the whole call:
  the kernels, the transfers and the compaction of the contact sets; the
  best of ``--repeat`` runs);
* the GPU/CPU agreement on the ``--n`` ICs (the GPU's first ``--n`` throws):
  the fractions, with counts, of throws with the same outcome, the same
  step count, the same contact-set sequence and the same status;
* the chaos floor: the CPU against itself from the same ICs nudged by
  1e-15 relative (every component times 1 ± 1e-15, random signs), the
  outcome agreement a change of a few ulps of the ICs gives.  The GPU
  rounds differently from the CPU only in the device's sin, cos and exp
  (every kernel is compiled without fused multiply-adds on both), and the
  chaos amplifies that near the basins' borders as it
  amplifies the nudge: the GPU's differences are within the floor when
  they are no more frequent than the nudge's (the line says which, with a
  2-σ allowance for the counts).

The ICs are the seed slice (``dicetrace.ics.seed_slice``), x, y uniform in
[0, 20]² (rng ``--seed``).  Then, unless ``--skip-scan``, the wall time of
``dicetrace scan --window 0,20,0,20 --res 1000`` (the seed preset, or
``--scan-preset physical``; the same window; the whole command in a new
process, numba-cuda loading its kernel
from its cache there (or compiling it) and the Parquet written to a
temporary folder) with ``--device cpu``
and ``--device cuda`` (``--scan-devices``), where the CLI has ``--device``:
the GPU three times, the first loading (or compiling) the kernel, then with
one CUDA stream a GPU (``DICETRACE_GPU_STREAMS=1``: no overlap of a chunk's
copies and host work with the next chunk's kernel; not with
``--no-scan-overlap``) and with the default again, from a warm cache, and
the gain of the overlap on the wall time (the two scans' rows compared).
The throughput lines likewise give the GPU's rate with one stream beside the
default, and whether the results are identical (they must be).

Without a GPU it prints one line saying why and exits 2.  Under numba-cuda's
simulator (``NUMBA_ENABLE_CUDASIM=1``) it runs with ``--quick`` sizes only:
the "GPU" is Python on the CPU (with ``NUMBA_DISABLE_JIT=1``, which the
script sets there unless given: the physics then runs as plain Python on
both devices), and its figures mean nothing (a check that the script and
the device path run).

``--write FILE.json`` also writes every figure printed, with the machine and
the versions, to a JSON file (rewritten after each part, so a run cut short
keeps what it measured): the results file a README figure is quoted from.

Usage: ``python benchmarks/bench_gpu.py [--n 100000] [--rate-n 1000000]
[--presets seed,physical] [--repeat 1] [--skip-scan] [--scan-preset seed] [--scan-devices cpu,cuda]
[--no-scan-overlap] [--quick] [--write FILE.json]``.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from machine import cpu_model  # benchmarks/machine.py

if os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0"):
    # the simulator runs the kernels as Python, which calls the physics: as plain Python too (before numba loads)
    os.environ.setdefault("NUMBA_DISABLE_JIT", "1")

PROG = "bench_gpu"
#: Relative size of the nudge that measures the chaos floor.
NUDGE = 1e-15
#: ICs of the first (compiling) call on each device.
WARM_N = 64
#: ``--quick``: agreement ICs, throughput ICs, first-call ICs and the scan's grid points per axis.
QUICK = dict(n=8, rate_n=8, warm_n=2, scan_res=8)


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse's own prints the usage too)
        sys.stderr.write(f"{PROG}: error: {message}\n")
        sys.exit(2)


def _fail(message: str) -> None:
    sys.stderr.write(f"{PROG}: error: {message}\n")
    sys.exit(2)


def _simulated() -> bool:
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


def _jit_disabled() -> bool:
    return os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0")


#: What a CPU worker hands back (``--cpu-worker``): the fields the agreement reads.
_FIELDS = ("outcome", "steps", "status_code", "set_offsets", "sets")


def cpu_batch(ics, preset: str):
    """``simulate_batch(ics, config=preset, device="cpu")`` on all numba threads.

    With ``NUMBA_DISABLE_JIT=1`` (the simulator's setting) the CPU's kernels
    cannot run as plain Python (their state records are numpy structs):
    they run compiled in a child process without the simulator, whose
    result comes back through a temporary file.
    """
    if not _jit_disabled():
        from dicetrace.simulate import simulate_batch

        return simulate_batch(ics, config=preset, device="cpu")
    with tempfile.TemporaryDirectory(prefix="bench_gpu_cpu_") as d:
        np.save(Path(d) / "ics.npy", np.asarray(ics, dtype=np.float64))
        env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0", "NUMBA_DISABLE_JIT": "0"}
        r = subprocess.run([sys.executable, __file__, "--cpu-worker", d, "--presets", preset], env=env,
                           capture_output=True, text=True)
        if r.returncode != 0:
            sys.stderr.write(r.stderr)
            raise RuntimeError(f"the CPU worker failed (exit {r.returncode})")
        with np.load(Path(d) / "out.npz") as z:
            return SimpleNamespace(device="cpu", **{k: z[k] for k in _FIELDS})


def _cpu_worker(folder: str, preset: str) -> int:
    from dicetrace.simulate import simulate_batch

    r = simulate_batch(np.load(Path(folder) / "ics.npy"), config=preset, device="cpu")
    np.savez(Path(folder) / "out.npz", **{k: getattr(r, k) for k in _FIELDS})
    return 0


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def slice_ics(n: int, seed: int):
    """n ICs of the seed slice, x, y uniform in [0, 20]² (rng ``seed``)."""
    from dicetrace.ics import seed_slice

    rng = np.random.default_rng(seed)
    return seed_slice(rng.uniform(0.0, 20.0, n), rng.uniform(0.0, 20.0, n))


def nudged(ics, seed: int) -> np.ndarray:
    """``ics`` with every component times 1 ± ``NUDGE`` (random signs, rng ``seed``)."""
    rng = np.random.default_rng(seed)
    ics = np.asarray(ics, dtype=np.float64)
    return ics * (1.0 + NUDGE * rng.choice((-1.0, 1.0), size=ics.shape))


def same_sequences(a, b, n: int) -> np.ndarray:
    """Per throw of the first n: whether results a and b have the same contact-set sequence."""
    oa, ob = a.set_offsets, b.set_offsets
    la, lb = np.diff(oa[: n + 1]), np.diff(ob[: n + 1])
    out = la == lb
    for i in np.flatnonzero(out):
        out[i] = np.array_equal(a.sets[oa[i] : oa[i + 1]], b.sets[ob[i] : ob[i + 1]])
    return out


def agreement(a, b, n: int) -> dict:
    """name -> per-throw bool array over the first n throws of results a and b."""
    return {
        "outcomes equal": a.outcome[:n] == b.outcome[:n],
        "steps equal": a.steps[:n] == b.steps[:n],
        "contact sequences equal": same_sequences(a, b, n),
        "status equal": a.status_code[:n] == b.status_code[:n],
    }


def _frac(mask: np.ndarray) -> str:
    k, n = int(mask.sum()), len(mask)
    return f"{100.0 * k / max(n, 1):9.4f} % ({k:,} of {n:,})"


def within_floor(d_gpu: int, d_floor: int) -> bool:
    """Whether d_gpu differing outcomes are no more than the floor's d_floor, within 2 σ of the two counts."""
    return d_gpu <= d_floor + 2.0 * math.sqrt(d_gpu + d_floor)


def _timed(fn, repeat: int = 1):
    """fn()'s result and its best wall time of ``repeat`` calls."""
    best = math.inf
    for _ in range(max(1, repeat)):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return out, best


def _count(mask: np.ndarray) -> list[int]:
    """[k, n]: how many of the n throws of ``mask`` hold."""
    return [int(mask.sum()), int(len(mask))]


def bench_preset(preset: str, n: int, rate_n: int, warm_n: int, seed: int, repeat: int = 1) -> dict:
    """Print the preset's figures (see the module docstring) and return them, as ``--write`` stores them."""
    import numba

    from dicetrace.simulate import simulate_batch

    rate_n = max(rate_n, n)
    ics = slice_ics(rate_n, seed)
    agree_ics = ics[:n]
    threads = numba.get_num_threads()
    print(f"\n== {preset} ==", flush=True)
    _, t_gpu0 = _timed(lambda: simulate_batch(ics[:warm_n], config=preset, device="cuda"))
    _, t_cpu0 = _timed(lambda: cpu_batch(ics[:warm_n], preset))
    print(f"  first call ({warm_n} ICs): GPU {t_gpu0:.2f} s (compiles the kernel, or loads it from the cache); "
          f"CPU {t_cpu0:.2f} s (loads the kernels from numba's cache, or compiles them)", flush=True)
    gpu, t_gpu = _timed(lambda: simulate_batch(ics, config=preset, device="cuda"), repeat)
    print(f"  GPU  {gpu.device:<32} {rate_n / t_gpu:>12,.0f} throws/s  ({rate_n:,} ICs in {t_gpu:.2f} s, "
          f"{gpu.steps.mean():.0f} steps per throw)", flush=True)
    cpu, t_cpu = _timed(lambda: cpu_batch(agree_ics, preset), repeat)
    print(f"  CPU  {f'{threads} numba threads':<32} {n / t_cpu:>12,.0f} throws/s  ({n:,} ICs in {t_cpu:.2f} s, "
          f"{cpu.steps.mean():.0f} steps per throw)", flush=True)
    print(f"  GPU/CPU throughput ×{(rate_n / t_gpu) / (n / t_cpu):.1f}", flush=True)
    with _streams(1):
        one, t_one = _timed(lambda: simulate_batch(ics, config=preset, device="cuda"), repeat)
    same = all(np.array_equal(getattr(one, k), getattr(gpu, k))
               for k in ("outcome", "steps", "status_code", "set_offsets", "sets", "set_steps"))
    print(f"  GPU, one stream a GPU (no overlap) {rate_n / t_one:>10,.0f} throws/s  ({rate_n:,} ICs in {t_one:.2f} s): "
          f"the overlap of {_streams_default()} streams gains ×{t_one / t_gpu:.2f}; results "
          + ("identical" if same else "DIFFERENT (a defect)"), flush=True)
    print(f"  GPU vs CPU, {n:,} ICs of the seed slice, x, y uniform in [0, 20]² (rng {seed}):")
    agree = agreement(gpu, cpu, n)
    for name, mask in agree.items():
        print(f"    {name:<26} {_frac(mask)}")
    floor = cpu_batch(nudged(agree_ics, seed + 1), preset)
    floor_mask = agreement(floor, cpu, n)["outcomes equal"]
    print(f"  chaos floor, CPU vs CPU from the ICs nudged by {NUDGE:g} relative:")
    print(f"    {'outcomes equal':<26} {_frac(floor_mask)}", flush=True)
    d_gpu = int(n - (gpu.outcome[:n] == cpu.outcome[:n]).sum())
    d_floor = int(n - floor_mask.sum())
    verdict = "within" if within_floor(d_gpu, d_floor) else "ABOVE"
    print(f"  {preset} {verdict} its chaos floor at a {NUDGE:g} nudge: {d_gpu:,} outcomes differ GPU vs CPU, "
          f"{d_floor:,} CPU vs the nudged CPU (of {n:,})")
    failed = int(((cpu.status_code == 0) & (gpu.status_code[:n] != 0)).sum())
    if failed:
        print(f"  {failed:,} throws settle on the CPU but not on the GPU")
    return {
        "ics": f"seed slice, x, y uniform in [0, 20]^2, rng {seed}",
        "first_call": {"n": warm_n, "gpu_s": t_gpu0, "cpu_s": t_cpu0},
        "gpu": {"device": gpu.device, "n": rate_n, "seconds": t_gpu, "throws_per_s": rate_n / t_gpu,
                "steps_per_throw": float(gpu.steps.mean()), "best_of": repeat},
        "cpu": {"numba_threads": threads, "n": n, "seconds": t_cpu, "throws_per_s": n / t_cpu,
                "steps_per_throw": float(cpu.steps.mean()), "best_of": repeat},
        "gpu_over_cpu_throughput": (rate_n / t_gpu) / (n / t_cpu),
        "gpu_one_stream": {"streams_default": _streams_default(), "throws_per_s": rate_n / t_one,
                           "overlap_gain": t_one / t_gpu, "results_identical": bool(same)},
        "agreement": {name: _count(mask) for name, mask in agree.items()},
        "chaos_floor": {"nudge": NUDGE, "outcomes equal": _count(floor_mask)},
        "outcomes_differing": {"gpu_vs_cpu": d_gpu, "cpu_vs_nudged_cpu": d_floor},
        "within_chaos_floor": verdict == "within",
        "settle_on_cpu_not_gpu": failed,
    }


class _streams:
    """Context: batches on ``n`` CUDA streams a GPU (``DICETRACE_GPU_STREAMS``, read at each batch)."""

    def __init__(self, n: int | None):
        self.n = n

    def __enter__(self):
        self.old = os.environ.get("DICETRACE_GPU_STREAMS")
        if self.n is None:
            os.environ.pop("DICETRACE_GPU_STREAMS", None)
        else:
            os.environ["DICETRACE_GPU_STREAMS"] = str(self.n)

    def __exit__(self, *exc):
        if self.old is None:
            os.environ.pop("DICETRACE_GPU_STREAMS", None)
        else:
            os.environ["DICETRACE_GPU_STREAMS"] = self.old


def _streams_default() -> int:
    from dicetrace.core.gpu import streams_per_device

    return streams_per_device()


def _cli() -> list[str]:
    return [sys.executable, "-m", "dicetrace.cli"]


def _last_line(text: str) -> str:
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else "no output"


def bench_scan(res: int, window: str, preset: str = "seed", devices=("cpu", "cuda"), overlap: bool = True) -> dict:
    """Print the timed scans' wall times (see the module docstring) and return them, as ``--write`` stores them."""
    env = {**os.environ, "COLUMNS": "250", "TERM": "dumb", "NO_COLOR": "1"}
    print(f"\n== dicetrace scan --window {window} --res {res} ({preset} preset) ==", flush=True)
    found: dict = {"window": window, "res": res, "preset": preset, "wall_s": {}}
    try:
        helped = subprocess.run([*_cli(), "scan", "--help"], capture_output=True, text=True, timeout=300, env=env)
    except (OSError, subprocess.TimeoutExpired) as exc:
        print(f"  scan: not available ({type(exc).__name__}: {exc})")
        return {**found, "not_available": f"{type(exc).__name__}: {exc}"}
    if helped.returncode != 0:
        print(f"  scan: not available (the CLI does not start: {_last_line(helped.stderr)})")
        return {**found, "not_available": _last_line(helped.stderr)}
    if "--device" not in helped.stdout:
        print("  scan --device: not available (this CLI's scan has no --device)")
        return {**found, "not_available": "no --device"}
    tmp = Path(tempfile.mkdtemp(prefix="bench_gpu_scan_"))
    # the GPU three times: the first loads (or compiles) the kernel; then one stream a GPU (no overlap of one
    # chunk's copies and host work with the next one's kernel) and the default again, from a warm cache
    runs = [("cpu", "cpu", None), ("cuda", "cuda", None), ("cuda", "cuda, 1 stream", 1), ("cuda", "cuda, again", None)]
    runs = [r if (r[0] in devices and (overlap or r[2] is None)) else None for r in runs]  # kept in place: 2 vs 3
    walls: dict = {}
    try:
        for i, run in enumerate(runs):
            if run is None:
                continue
            device, label, streams = run
            out = tmp / str(i)
            cmd = [*_cli(), "scan", "--window", window, "--res", str(res), "--preset", preset, "--out", str(out),
                   "--device", device, "--yes"]
            run_env = {k: v for k, v in env.items() if k != "DICETRACE_GPU_STREAMS"}
            if streams is not None:
                run_env["DICETRACE_GPU_STREAMS"] = str(streams)
            t = time.perf_counter()
            try:
                r = subprocess.run(cmd, capture_output=True, text=True, timeout=1800, env=run_env)
            except subprocess.TimeoutExpired:
                print(f"  {label:<15} timed out after 1800 s")
                continue
            wall = time.perf_counter() - t
            if r.returncode != 0:
                print(f"  {label:<15} failed (exit {r.returncode}): {_last_line(r.stderr)}")
                continue
            walls[i] = wall
            found["wall_s"][label] = wall
            print(f"  {label:<15} {wall:8.2f} s wall, {res * res:,} ICs (the whole command: start-up, "
                  + ("loading or compiling the GPU kernel, " if device == "cuda" else "loading the kernels, ")
                  + "throws, Parquet)", flush=True)
        if 2 in walls and 3 in walls:
            same = _same_rows(tmp / "2", tmp / "3")
            print(f"  overlap (DICETRACE_GPU_STREAMS default {_streams_default()} against 1, warm cache): "
                  f"×{walls[2] / walls[3]:.2f} on the scan's wall time; rows "
                  + ("identical" if same else "DIFFERENT (a defect)"), flush=True)
            found["overlap_gain"] = walls[2] / walls[3]
            found["overlap_rows_identical"] = bool(same)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return found


def _same_rows(a: Path, b: Path) -> bool:
    """Whether two scan folders hold the same rows (outcome, status, steps, contact sequences)."""
    from dicetrace.scan import read_scan

    x, y = read_scan(a), read_scan(b)
    cols = [c for c in ("ic_id", "outcome", "status", "steps", "contact_sequence") if c in x.columns]
    return len(x) == len(y) and x[cols].equals(y[cols])


def main(argv=None) -> int:
    ap = _Parser(prog=PROG, description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100000, help="ICs for the agreement and the CPU's rate (default 100000)")
    ap.add_argument("--rate-n", type=int, default=1000000, help="ICs for the GPU's rate (default 1000000)")
    ap.add_argument("--presets", default="seed,physical", help="comma-separated presets (default seed,physical)")
    ap.add_argument("--scan-res", type=int, default=1000, help="grid points per axis of the timed scan (default 1000)")
    ap.add_argument("--scan-window", default="0,20,0,20",
                    help="window of the timed scan, as dicetrace scan --window takes it (default 0,20,0,20)")
    ap.add_argument("--skip-scan", action="store_true", help="do not time dicetrace scan")
    ap.add_argument("--scan-preset", default="seed", help="the timed scan's preset (default seed)")
    ap.add_argument("--scan-devices", default="cpu,cuda", help="the devices of the timed scan (default cpu,cuda)")
    ap.add_argument("--scan-overlap", action=argparse.BooleanOptionalAction, default=True,
                    help="also time the GPU's scan on one CUDA stream, for the gain of the overlap (default: yes)")
    ap.add_argument("--seed", type=int, default=7, help="rng seed of the ICs (default 7)")
    ap.add_argument("--repeat", type=int, default=1, help="the rates are the best of this many runs (default 1)")
    ap.add_argument("--quick", action="store_true", help="tiny sizes, to check that the script runs (for tests)")
    ap.add_argument("--write", metavar="FILE.json", help="also write the figures to this JSON file (after each part)")
    ap.add_argument("--cpu-worker", metavar="DIR", help=argparse.SUPPRESS)  # see cpu_batch
    args = ap.parse_args(argv)
    if args.cpu_worker:
        return _cpu_worker(args.cpu_worker, args.presets)

    from dicetrace.params import PRESETS

    presets = [p.strip() for p in args.presets.split(",") if p.strip()]
    unknown = [p for p in presets if p not in PRESETS]
    if unknown or not presets:
        _fail(f"--presets: unknown preset(s) {', '.join(unknown) or '(none given)'} (choose from {', '.join(PRESETS)})")
    if args.scan_preset not in PRESETS:
        _fail(f"--scan-preset: unknown preset {args.scan_preset!r} (choose from {', '.join(PRESETS)})")
    scan_devices = tuple(d.strip() for d in args.scan_devices.split(",") if d.strip())
    if not scan_devices or set(scan_devices) - {"cpu", "cuda"}:
        _fail(f"--scan-devices: choose from cpu, cuda (comma-separated), got {args.scan_devices!r}")
    for name, v, lo in (("--n", args.n, 1), ("--rate-n", args.rate_n, 1), ("--scan-res", args.scan_res, 2),
                        ("--repeat", args.repeat, 1)):
        if v < lo:
            _fail(f"{name} must be at least {lo}, got {v}")

    sim = _simulated()
    from dicetrace.devices import device_label, gpu_unavailable_reason

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        why = gpu_unavailable_reason()
    if why is not None:
        sys.stderr.write(f"{PROG}: no GPU to benchmark: {why}\n")
        return 2
    n, rate_n, warm_n, scan_res = args.n, args.rate_n, WARM_N, args.scan_res
    if args.quick or sim:
        n, rate_n, warm_n, scan_res = QUICK["n"], QUICK["rate_n"], QUICK["warm_n"], QUICK["scan_res"]

    import numba

    found = {
        "machine": {"cpu": cpu_model(), "cpus": os.cpu_count(), "numba_threads": numba.get_num_threads(),
                    "gpu": device_label("cuda"), "python": platform.python_version(), "numpy": np.__version__,
                    "numba": numba.__version__, "numba_cuda": _version("numba-cuda"),
                    "load_average": os.getloadavg()[0]},
        "simulator": sim, "quick": bool(args.quick or sim), "argv": sys.argv[1:],
        "started": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "presets": {},
    }
    write = (lambda: _write_json(args.write, found)) if args.write else (lambda: None)
    write()  # a bad path fails now, before the run
    print(f"machine: {cpu_model()}, {os.cpu_count()} CPUs, {numba.get_num_threads()} numba threads; "
          f"GPU {device_label('cuda')}")
    print(f"python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
          f"numba-cuda {_version('numba-cuda')}; load average {os.getloadavg()[0]:.2f}")
    if sim:
        print("numba-cuda's simulator (NUMBA_ENABLE_CUDASIM=1): the 'GPU' runs as Python on the CPU, at --quick "
              f"sizes (NUMBA_DISABLE_JIT={os.environ.get('NUMBA_DISABLE_JIT')}; the CPU side compiled, in a child "
              "process where the JIT is off); every figure below is meaningless, the run only checks the script "
              "and the device path")
    elif args.quick:
        print("--quick sizes: the figures below mean little")
    for preset in presets:
        found["presets"][preset] = bench_preset(preset, n, rate_n, warm_n, args.seed,
                                                1 if (args.quick or sim) else args.repeat)
        write()
    if args.skip_scan:
        print("\nscan: skipped (--skip-scan)")
    else:
        found["scan"] = bench_scan(scan_res, args.scan_window, args.scan_preset, scan_devices, args.scan_overlap)
    found["finished"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    write()
    return 0


def _write_json(path: str, found: dict) -> None:
    """``found`` into ``path`` atomically (a temporary beside it, renamed): one line and exit 2 where it cannot."""
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(json.dumps(found, indent=1) + "\n")
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        _fail(f"--write {path!r}: {exc.strerror or exc}")


if __name__ == "__main__":
    sys.exit(main())
