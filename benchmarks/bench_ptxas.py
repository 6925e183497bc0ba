"""Registers, spills and local memory per thread of the GPU kernels, from NVIDIA's ``ptxas -v`` (no GPU needed).

Compiles each kernel of ``dicetrace.core.gpu`` to PTX for a compute capability
(default 9.0, an H100/H200) with NVVM, strictly (``-fma=0``, as the kernels
run), then assembles it with ``ptxas -v`` and prints what it reports for the
kernel's entry function: registers per thread, spill stores and loads, and
the stack frame (local memory) per thread.  A kernel of 255 registers lets an
SM keep 8 of its 64 warps; spills go to local memory.

Needs numba-cuda with NVIDIA's compiler wheels (``pip install 'numba-cuda[cu12]'``:
NVVM, and ``ptxas`` in ``nvidia/cuda_nvcc/bin``); without them it says so in
one line and exits 2.

Usage: ``python benchmarks/bench_ptxas.py [--cc 9.0] [--only TEXT] [--ptx DIR] [--write FILE.json]``
(``--only``: the kernels whose label contains TEXT; ``--ptx``: keep each kernel's PTX there.)
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import subprocess
import sys
import tempfile
import types
from pathlib import Path

#: (label, preset, integrator or None for the preset's, events, held)
KERNELS = (
    ("seed kernel (seed)", "seed", None, False, False),
    ("general kernel (physical: contact-tsit5)", "physical", None, False, False),
    ("events kernel (physical: contact-tsit5)", "physical", None, True, False),
    ("held general kernel (physical: contact-tsit5)", "physical", None, False, True),
    ("general kernel (seed, verlet)", "seed", "verlet", False, False),
    ("general kernel (physical, contact-dop853)", "physical", "contact-dop853", False, False),
)


def _ptxas() -> str | None:
    for root in sys.path:
        hits = glob.glob(os.path.join(root, "nvidia", "cuda_nvcc", "bin", "ptxas"))
        if hits:
            return hits[0]
    return None


def parse(report: str, entry: str) -> dict:
    """What ``ptxas -v`` says of the entry function whose mangled name contains ``entry``."""
    lines = report.splitlines()
    out = {}
    for i, line in enumerate(lines):
        if "Compiling entry function" in line and entry in line:
            for nxt in lines[i + 1 : i + 6]:
                m = re.search(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads", nxt)
                if m:
                    out.update(stack_bytes=int(m[1]), spill_stores=int(m[2]), spill_loads=int(m[3]))
                m = re.search(r"Used (\d+) registers", nxt)
                if m:
                    out["registers"] = int(m[1])
            break
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cc", default="9.0", help="compute capability (default 9.0)")
    ap.add_argument("--write", type=Path, help="write the figures as JSON to this file")
    ap.add_argument("--only", metavar="TEXT", help="measure only the kernels whose label contains TEXT")
    ap.add_argument("--ptx", type=Path, metavar="DIR", help="keep each kernel's PTX in this folder")
    args = ap.parse_args()
    chosen = [k for k in KERNELS if args.only is None or args.only in k[0]]
    if not chosen:
        print(f"bench_ptxas: no kernel's label contains {args.only!r}", file=sys.stderr)
        return 2
    cc = tuple(int(x) for x in args.cc.split("."))
    ptxas = _ptxas()
    if ptxas is None:
        print("bench_ptxas: no ptxas here (pip install 'numba-cuda[cu12]' brings it)", file=sys.stderr)
        return 2
    import numba.cuda.cudadrv.devices as devs
    import numba.cuda.dispatcher as d

    fake = types.SimpleNamespace(compute_capability=cc)
    d.get_current_device = lambda: fake  # the compute capability is all compiling asks of a device
    devs.get_context = lambda *a, **k: types.SimpleNamespace(device=fake)
    import numpy as np
    from numba import cuda, typeof
    from numba.cuda.cudadrv import nvvm

    from dicetrace.core import _compat, gpu
    from dicetrace.core.kernels import SLICE_STEPS, kernels_for
    from dicetrace.core.state import MOTION, new_work
    from dicetrace.params import make_config

    results = {}
    for label, preset, integ, events, held in chosen:
        cfg = make_config(preset, **({} if integ is None else {"integrator": integ}))
        kin = cfg.kernel_inputs(np.zeros((2, 6)))
        seed = not events and not held and gpu.uses_seed_kernel(kin.params, kin.off0, kin.integrator_id)
        kernel = gpu._kernel(kin.integrator_id, seed, events, held)
        o = [np.zeros(2, np.int8), np.zeros(2, np.int64), np.zeros(2, np.int8), np.zeros(2, np.int64),
             np.zeros(16, np.uint8), np.zeros(16, np.int32)]
        work = kernels_for(kin.integrator_id).scheme.WORK
        n = 2 if held else 0
        args_ = (kin.ics, kin.off0, kin.params, 8, *o, SLICE_STEPS) if seed else (
            kin.ics, kin.off0, kin.params, 8, np.zeros(n, MOTION), new_work(work, n), *o, np.zeros(16 if events else 0),
            np.zeros((0, 33)), np.zeros((0, 24)), np.zeros((0, 6)), False, SLICE_STEPS, 0)
        sig = tuple(typeof(a) for a in args_)
        with _compat.nvvm_without_fma(nvvm):
            ptx, _ = cuda.compile_ptx(kernel.py_func, sig, cc=cc)
        with tempfile.NamedTemporaryFile("w", suffix=".ptx", delete=False) as f:
            f.write(ptx)
        rep = subprocess.run([ptxas, f"-arch=sm_{cc[0]}{cc[1]}", "-v", f.name, "-o", os.devnull],
                             capture_output=True, text=True)
        if args.ptx:
            args.ptx.mkdir(parents=True, exist_ok=True)
            os.replace(f.name, args.ptx / (re.sub(r"\W+", "_", label).strip("_") + ".ptx"))
        else:
            os.unlink(f.name)
        entry = kernel.py_func.__name__
        fig = parse(rep.stderr, entry)
        fig["local_records_bytes"] = 0 if (seed or held) else MOTION.itemsize + work.itemsize
        results[label] = fig
        print(f"{label:<48} {fig.get('registers', '?'):>4} registers, {fig.get('spill_stores', '?')} B spill stores, "
              f"{fig.get('spill_loads', '?')} B spill loads, {fig.get('stack_bytes', '?')} B stack frame"
              + (f" (records {fig['local_records_bytes']} B)" if fig["local_records_bytes"] else ""), flush=True)
    if args.write:
        head = subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True,
                              cwd=Path(__file__).resolve().parent).stdout.strip()
        args.write.write_text(json.dumps(dict(cc=args.cc, commit=head or None, kernels=results), indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
