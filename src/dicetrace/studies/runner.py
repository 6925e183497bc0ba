"""Running writeup studies: compute, render, results JSON, timings, then the report.

:func:`run` runs studies one after the other in this process (numba
compiles once); they share simulated grids through ``OUT/cache``.  Each
writes ``OUT/results/<study>.json`` and its figures; the timings go to
``OUT/results/run_all.json``, and ``OUT/REPORT.md`` is rebuilt from every
``OUT/results/*.json`` present: the whole report when every study has
results, else the sections of those that have (:func:`dicetrace.studies.report.build`).
"""

from __future__ import annotations

import json
import os
import platform
import time
from importlib.metadata import version
from pathlib import Path

from dicetrace import memory  # memory.available_memory is looked up at each call (tests patch it)
from dicetrace.devices import resolve_device, use_device
from dicetrace.sinks._common import human_bytes
from dicetrace.studies import WRITEUP_STUDIES, resolve, study_module
from dicetrace.studies.context import Context, Options, Output, write_json
from dicetrace.studies.outputs import write_text
from dicetrace.studies.report import build
from dicetrace.studies.study_animation import NZ

#: The timings file (the report reads ``run_all.*``).
TIMINGS = "run_all"


#: Memory per node of the largest grid of a run, bytes: study a (cells) at --res 601 peaked ~600 B per node of its
#: main grid (four windows held with their cell tables); rounded up.
BYTES_PER_GRID_NODE = 1024


def largest_grid(names, options: Options) -> int:
    """Nodes of the largest grid a run of studies ``names`` simulates with ``options.res`` (its main grid: res²,
    res² × the frames of study i); 0 without ``--res`` (the studies' own sizes, which fit)."""
    if options.res is None:
        return 0

    nz = NZ[1 if options.quick else 0] if "animation" in names else 1
    return int(options.res) ** 2 * nz


def check_memory(names, options: Options) -> None:
    """Refuse (ValueError naming --res) a run whose largest grid will not fit in the available memory."""
    nodes = largest_grid(names, options)
    need, avail = nodes * BYTES_PER_GRID_NODE, memory.available_memory()
    if nodes and avail is not None and need > avail:
        raise ValueError(f"--res {options.res}: the largest grid of this run ({nodes:,} nodes) needs about "
                         f"{human_bytes(need)} of memory, {human_bytes(avail)} available: use a smaller --res")


def run_study(name: str, options: Options, out: Path) -> dict:
    """Compute and render one writeup study into ``out``; returns what its JSON holds."""
    mod = study_module(name)
    ctx = Context(name, options, Path(out) / "cache")
    device = resolve_device(options.device)  # once (the command line passes it resolved already)
    with use_device(device):  # every batch of the study, however deep, runs there
        computed = mod.compute(ctx)
    output = Output(out)
    mod.render(computed, output)
    results = {"study": name, "quick": options.quick, "seed": options.seed, "figures": output.figures,
               "tables": output.tables, **computed.results}
    results["wall_s"] = time.perf_counter() - ctx.t0
    results["n_throws_simulated"] = int(ctx.n_throws)
    results["device"] = device.label
    path = write_json(output.res_dir / f"{name}.json", results)
    ctx.log(f"wrote {path} ({results['wall_s']:.1f} s)")
    return results


def _environment() -> dict:
    info = {"cpu_count": os.cpu_count(), "machine": platform.machine(), "python": platform.python_version(),
            "finished": time.strftime("%Y-%m-%d %H:%M:%S %Z")}
    try:
        import numba  # lazy: keeps `dicetrace --help` fast (imports numba)

        info["numba_threads"] = numba.get_num_threads()
        info["numba"] = numba.__version__
    except ImportError:  # pragma: no cover
        pass
    try:
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
    write_text(path, json.dumps(info, indent=1), "timings file")
    if report:
        build(out)
    print(f"=== done: {', '.join(names)} in {total:.1f} s ===", flush=True)
    return info
