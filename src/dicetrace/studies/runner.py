"""Running writeup studies: compute, render, results JSON, timings, then the report.

:func:`run` runs studies one after the other in this process (numba
compiles once); they share simulated grids through ``OUT/cache``.  Each
writes ``OUT/results/<study>.json`` and its figures; the timings go to
``OUT/results/run_all.json``, and ``OUT/REPORT.md`` is rebuilt from every
``OUT/results/*.json`` present.
"""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

from dicetrace.studies import WRITEUP_STUDIES, resolve, study_module
from dicetrace.studies.context import Context, Options, Output, write_json

#: The timings file (the report reads ``run_all.*``).
TIMINGS = "run_all"


def run_study(name: str, options: Options, out: Path) -> dict:
    """Compute and render one writeup study into ``out``; returns what its JSON holds."""
    mod = study_module(name)
    ctx = Context(name, options, Path(out) / "cache")
    computed = mod.compute(ctx)
    output = Output(out)
    mod.render(computed, output)
    results = {"study": name, "quick": options.quick, "seed": options.seed, "figures": output.figures,
               "tables": output.tables, **computed.results}
    results["wall_s"] = time.perf_counter() - ctx.t0
    results["n_throws_simulated"] = int(ctx.n_throws)
    path = write_json(output.res_dir / f"{name}.json", results)
    ctx.log(f"wrote {path} ({results['wall_s']:.1f} s)")
    return results


def _environment() -> dict:
    info = {"cpu_count": os.cpu_count(), "machine": platform.machine(), "python": platform.python_version(),
            "finished": time.strftime("%Y-%m-%d %H:%M:%S %Z")}
    try:
        import numba

        info["numba_threads"] = numba.get_num_threads()
        info["numba"] = numba.__version__
    except ImportError:  # pragma: no cover
        pass
    try:
        from importlib.metadata import version

        info["dicetrace"] = version("dicetrace")
    except Exception:  # pragma: no cover - not installed as a distribution
        pass
    return info


def run(studies, *, options: Options = Options(), out: Path, report: bool = True) -> dict:
    """Run studies (names, letters or ``all``) in order into ``out``; returns the timings record."""
    names = resolve(studies)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    timings = {}
    t_all = time.perf_counter()
    for name in names:
        t0 = time.perf_counter()
        print(f"=== {name} ===", flush=True)
        run_study(name, options, out)
        timings[name] = time.perf_counter() - t0
    total = time.perf_counter() - t_all
    info = {"studies": names, "quick": options.quick, "timings_s": timings, "total_s": total, **_environment()}
    path = out / "results" / f"{TIMINGS}.json"
    if path.exists() and set(names) != set(WRITEUP_STUDIES):  # a partial run keeps the other studies' timings
        try:
            prev = json.loads(path.read_text())
        except ValueError:
            prev = {}
        if prev.get("quick") == options.quick:
            merged = {**prev.get("timings_s", {}), **timings}
            info.update(timings_s=merged, total_s=sum(merged.values()), studies=list(merged))
    path.write_text(json.dumps(info, indent=1))
    if report:
        from dicetrace.studies.report import build

        build(out)
    print(f"=== done: {', '.join(names)} in {total:.1f} s ===", flush=True)
    return info
