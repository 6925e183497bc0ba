"""Time to the explorer's first map and to a refined 256×256 view after a zoom, on the red-sea window.

Starts a real explorer (uvicorn on 127.0.0.1, a free port), warms the kernels
with 4×4 and 8×8 maps (numba's compile or cache load is reported separately), then
times over HTTP, as the page asks:

* red sea's passes as the page asks for them: preview (about 1/16 of the resolution) and
  coarse (about 1/4) as PNGs, then the refined map streamed in strips of rows
  (``/api/map.strips``): the time to its first strip and to its last,
* the same after a zoom to red-sea-2,

and then, for comparison, the batch kernel alone (``simulate_batch``, one call, in this
process) on all the refined view's ICs: what the explorer adds is the difference.  The
explorer runs in this process, so the CPU time it takes (all threads: ``time.process_time``)
is printed beside the wall time: on a shared machine it varies much less.

For ``--preset physical`` the preset's own integrator and tolerance (``contact-tsit5``,
2e-8 loosening at 10 /s) are used unless ``--integrator`` says otherwise.

``--device cuda`` runs the explorer's maps on a GPU (``--device auto``: a GPU where there is one);
``--write FILE`` also writes the figures, the device and the machine as JSON (the committed ones
are under ``benchmarks/results/``, rewritten only by naming them).

Usage: ``python benchmarks/bench_explore.py [--preset seed] [--res 256] [--integrator NAME] [--threads N]
[--device cpu|cuda|auto] [--no-fine] [--write FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
import urllib.request
from urllib.parse import urlencode

from dicetrace.explore import Explorer
from dicetrace.ics import WINDOWS

from machine import cpu_model  # benchmarks/machine.py


def _window(name: str) -> str:
    (x0, x1), (y0, y1) = WINDOWS[name]
    return f"{x0!r},{x1!r},{y0!r},{y1!r}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="seed")
    ap.add_argument("--integrator", default=None)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--device", default="cpu", choices=("cpu", "cuda", "auto"))
    ap.add_argument("--no-fine", action="store_true", help="time the preview and coarse passes only (slow presets)")
    ap.add_argument("--write", default=None, help="also write the figures as JSON to this file")
    a = ap.parse_args()
    record: dict = {"preset": a.preset, "integrator": a.integrator, "res": a.res, "windows": {}}
    with Explorer(window="red-sea", res=a.res, preset=a.preset, integrator=a.integrator, threads=a.threads,
                  device=a.device) as ex:
        base = f"http://127.0.0.1:{ex.port}"

        def query(window: str, **extra) -> str:
            q = {"window": window, "res": a.res, "preset": a.preset, "client": "bench", **extra}
            if a.integrator:
                q["integrator"] = a.integrator
            return urlencode(q)

        def fetch(window: str, pass_: str) -> float:
            t0 = time.perf_counter()
            with urllib.request.urlopen(f"{base}/api/map.png?{query(window, **{'pass': pass_})}", timeout=3600) as r:
                r.read()
                res = r.headers["X-Dicetrace-Res"]
            dt = time.perf_counter() - t0
            print(f"  {window:>32}  {pass_:7}  {res:>7}  {dt:7.3f} s")
            return dt

        def refine(window: str) -> tuple[float, float]:
            t0, c0 = time.perf_counter(), time.process_time()
            first = None
            with urllib.request.urlopen(f"{base}/api/map.strips?{query(window)}", timeout=3600) as r:
                for line in r:
                    msg = json.loads(line)
                    first = first if first is not None else time.perf_counter() - t0
            dt, cpu = time.perf_counter() - t0, time.process_time() - c0
            print(f"  {window:>32}  refined  {a.res},{a.res}  {dt:7.3f} s  (CPU {cpu:.3f} s; first strip {first:.3f} s; "
                  f"computed in {msg['wall_s']:.3f} s, {msg['reused']} points taken from the coarser passes)")
            return first, dt

        t0 = time.perf_counter()
        for warm in (4, 8):  # the single-throw path (up to 16 ICs) and the batch kernel
            q = {"res": warm, "preset": a.preset, "window": "0,0.1,0,0.1"}
            if a.integrator:
                q["integrator"] = a.integrator
            urllib.request.urlopen(f"{base}/api/map.png?{urlencode(q)}", timeout=3600).read()
        record["device"] = str(ex.device)  # its label: "cpu" or "cuda: <GPU name>"
        record["warm_s"] = time.perf_counter() - t0
        print(f"preset {a.preset}, {os.cpu_count()} CPUs, device {record['device']}; kernel compile or cache load "
              f"{record['warm_s']:.2f} s")
        out = []
        for name in ("red-sea", "red-sea-2"):
            p = fetch(_window(name), "preview")
            c = fetch(_window(name), "coarse")
            f1, f = (0.0, 0.0) if a.no_fine else refine(_window(name))
            refined = "" if a.no_fine else f", first refined strip {p + c + f1:.3f} s, refined {a.res}×{a.res} {p + c + f:.3f} s"
            out.append(f"first image {p:.3f} s, coarse {p + c:.3f} s{refined}")
            record["windows"][name] = {"first_image_s": p, "coarse_s": p + c,
                                       **({} if a.no_fine else {"first_strip_s": p + c + f1, "refined_s": p + c + f})}
        print(f"red sea: {out[0]} after the request; after a zoom to red-sea-2: {out[1]} (the page asks for the passes in turn)")
    if not a.no_fine:
        from dicetrace.simulate import simulate_batch

        v = ex.view
        grid, cfg = v.grid(), v.config()
        ics = grid.block(0, grid.size).ics
        t0, c0 = time.perf_counter(), time.process_time()
        simulate_batch(ics, config=cfg, l_convention=grid.slice.l_convention, threads=a.threads)
        record["batch_alone_s"] = time.perf_counter() - t0
        print(f"the batch kernel alone on red sea's {grid.size} refined ICs, one call: {record['batch_alone_s']:.3f} s "
              f"(CPU {time.process_time() - c0:.3f} s)")
    if a.write:
        record["machine"] = {"cpu": cpu_model(), "cores": os.cpu_count(), "python": platform.python_version()}
        record["load_average"] = list(os.getloadavg()[:2])
        record["measured"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        with open(a.write, "w") as f:
            json.dump(record, f, indent=1)
        print(f"wrote {a.write}")


if __name__ == "__main__":
    main()
