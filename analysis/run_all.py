"""Run the studies of ``analysis/`` and assemble ``REPORT.md``.

    python analysis/run_all.py                 # the full run, into analysis/
    python analysis/run_all.py --quick --out /tmp/quick   # the CI-sized run (< 60 s on 2 cores)
    python analysis/run_all.py cells settle    # some studies only (names or letters a..i)

Studies run one after the other in this process (numba compiles once) and
share simulated grids through ``OUT/cache``. Timings go to
``OUT/results/run_all.json``; the report is rebuilt from every
``OUT/results/*.json`` present.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

#: study name -> module (file analysis/<module>.py), in run order
STUDIES = {
    "cells": "a_cells",
    "fractal": "b_fractal",
    "repetition": "c_repetition",
    "topology": "d_topology",
    "damping": "e_damping",
    "vertices": "f_vertices",
    "settle": "g_settle",
    "wedge": "h_wedge",
    "animation": "i_animation",
}
ALIASES = {mod.split("_")[0]: name for name, mod in STUDIES.items()}


def resolve(names) -> list[str]:
    """Study names from names, letters (a..i) or 'all'; ValueError for an unknown one."""
    if not names or "all" in names:
        return list(STUDIES)
    out = []
    for n in names:
        key = n.strip().lower()
        key = ALIASES.get(key, key)
        if key not in STUDIES:
            raise ValueError(f"unknown study {n!r} (choose from all, {', '.join(STUDIES)}, or a..i)")
        if key not in out:
            out.append(key)
    return out


def run(studies, *, quick: bool = False, out: Path = HERE, res: int | None = None, seed: int | None = None,
        no_cache: bool = False, report: bool = True) -> dict:
    """Run studies in order; returns {study: wall seconds} plus totals."""
    names = resolve(studies)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    argv_common = ["--out", str(out)] + (["--quick"] if quick else []) + (["--no-cache"] if no_cache else [])
    if res is not None:
        argv_common += ["--res", str(res)]
    if seed is not None:
        argv_common += ["--seed", str(seed)]
    timings = {}
    t_all = time.perf_counter()
    for name in names:
        mod = importlib.import_module(STUDIES[name])
        t0 = time.perf_counter()
        print(f"=== {name} ({STUDIES[name]}.py) ===", flush=True)
        mod.main(argv_common)
        timings[name] = time.perf_counter() - t0
    total = time.perf_counter() - t_all
    info = {
        "studies": names,
        "quick": quick,
        "timings_s": timings,
        "total_s": total,
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "python": platform.python_version(),
        "finished": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
    }
    try:
        import numba

        info["numba_threads"] = numba.get_num_threads()
        info["numba"] = numba.__version__
    except Exception:  # pragma: no cover
        pass
    try:
        from importlib.metadata import version

        info["dicetrace"] = version("dicetrace")
    except Exception:  # pragma: no cover
        pass
    res_dir = out / "results"
    res_dir.mkdir(exist_ok=True)
    prev = {}
    p = res_dir / "run_all.json"
    if p.exists() and set(names) != set(STUDIES):  # a partial run keeps the other studies' timings
        try:
            prev = json.loads(p.read_text())
        except ValueError:
            prev = {}
        if prev.get("quick") == quick:
            merged = dict(prev.get("timings_s", {}))
            merged.update(timings)
            info["timings_s"] = merged
            info["total_s"] = sum(merged.values())
            info["studies"] = list(merged)
    p.write_text(json.dumps(info, indent=1))
    if report:
        import report as R

        R.build(out)
    print(f"=== done: {', '.join(names)} in {total:.1f} s ===", flush=True)
    return info


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("studies", nargs="*", help="studies to run (default all): " + ", ".join(STUDIES))
    ap.add_argument("--quick", action="store_true", help="small grids, for CI (< 60 s in all)")
    ap.add_argument("--out", type=Path, default=HERE, help="output folder (default analysis/)")
    ap.add_argument("--res", type=int, default=None, help="override every study's main grid size")
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--no-cache", action="store_true", help="re-simulate cached grids")
    ap.add_argument("--no-report", action="store_true", help="do not rebuild REPORT.md")
    a = ap.parse_args(argv)
    try:
        names = resolve(a.studies)
    except ValueError as e:
        ap.error(str(e))
    return run(names, quick=a.quick, out=a.out, res=a.res, seed=a.seed, no_cache=a.no_cache,
               report=not a.no_report)


if __name__ == "__main__":
    main(sys.argv[1:])
