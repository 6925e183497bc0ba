"""What the README's test command costs on a fresh clone: the whole run, the kernels' cold compile, pytest.

Clones this repository (its committed HEAD) into a temporary folder and runs
``bash .ci/run`` there with an empty kernel cache (``DICETRACE_CACHE_DIR``
pointing into the temporary folder), as CI does on a new clone; pip's and
Debian's package downloads are whatever this machine already has.  Prints the
wall time of the whole run, of the kernel compile (``tests/compile_kernels.py``'s
last line) and of pytest (its summary line), with the pytest summary and the
machine.  ``--write FILE`` also writes them as JSON: the committed figures the
README quotes are ``benchmarks/results/first_run.json``, rewritten only by
``python benchmarks/bench_first_run.py --write benchmarks/results/first_run.json``.

Usage: ``python benchmarks/bench_first_run.py [--write FILE] [--log FILE] [--keep]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import cpu_model  # benchmarks/machine.py

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", type=Path, default=None, help="also write the figures to this JSON file")
    ap.add_argument("--keep", action="store_true", help="keep the clone (its path is printed)")
    ap.add_argument("--log", type=Path, default=None, help="write the run's whole output to this file")
    args = ap.parse_args()
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True)
    if head.returncode != 0:
        print("bench_first_run: not a git checkout: nothing to clone", file=sys.stderr)
        return 2
    tmp = Path(tempfile.mkdtemp(prefix="dicetrace-first-run-"))
    clone = tmp / "dicetrace"
    try:
        subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
        env = {**os.environ, "CI": "true", "DICETRACE_CACHE_DIR": str(tmp / "kernels")}
        env.pop("VIRTUAL_ENV", None)
        load_before = os.getloadavg()[0]
        t0 = time.perf_counter()
        res = subprocess.run(["bash", ".ci/run"], cwd=clone, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        out = res.stdout + res.stderr
        kernels = re.findall(r"every kernel compiled or loaded in (\d+(?:\.\d+)?) s", out)
        summary = re.findall(r"^=+ (.*) in ([\d.]+)s(?: \([\d:]+\))? =+$", out, flags=re.M)
        figures = {
            "commit": head.stdout.strip(),
            "exit_code": res.returncode,
            "wall_s": round(wall, 1),
            "kernels_cold_s": float(kernels[-1]) if kernels else None,
            "pytest_s": float(summary[-1][1]) if summary else None,
            "pytest_summary": summary[-1][0] if summary else None,
            "machine": {"cpu": cpu_model(), "cores": os.cpu_count(), "python": platform.python_version(),
                        "system": platform.platform()},
            # other work on the machine slows the run: the 1-minute load average before and after it
            "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)],
            "measured": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        }
        print(json.dumps(figures, indent=1))
        if args.log is not None:
            args.log.write_text(out)
        if res.returncode != 0:  # what failed: pytest's short summary, else the end of the output
            i = res.stdout.rfind("short test summary info")
            print(res.stdout[i - 40:] if i >= 0 else out[-4000:], file=sys.stderr)
        if args.write is not None:
            args.write.parent.mkdir(parents=True, exist_ok=True)
            args.write.write_text(json.dumps(figures, indent=1) + "\n")
            print(f"wrote {args.write}")
        return 0 if res.returncode == 0 else 1
    finally:
        if args.keep:
            print(f"kept {clone}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
