"""Time to the explorer's first map and to a refined 256×256 view after a zoom, on the red-sea window.

Starts a real explorer (uvicorn on 127.0.0.1, a free port), warms the kernels
with 4×4 and 8×8 maps (numba's compile or cache load is reported separately), then
times over HTTP, as the page asks:

* red sea's three passes as the page asks for them: preview (1/16 resolution), coarse (1/4), refined,
* the same after a zoom to red-sea-2.

For ``--preset physical`` the preset's own integrator (contact-adaptive) is
used unless ``--integrator`` says otherwise.

Usage: ``python benchmarks/bench_explore.py [--preset seed] [--res 256] [--integrator NAME] [--threads N] [--no-fine]``.
"""

from __future__ import annotations

import argparse
import os
import time
import urllib.request
from urllib.parse import urlencode

from dicetrace.explore import Explorer
from dicetrace.ics import WINDOWS


def _window(name: str) -> str:
    (x0, x1), (y0, y1) = WINDOWS[name]
    return f"{x0!r},{x1!r},{y0!r},{y1!r}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="seed")
    ap.add_argument("--integrator", default=None)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--no-fine", action="store_true", help="time the preview and coarse passes only (slow presets)")
    a = ap.parse_args()
    with Explorer(window="red-sea", res=a.res, preset=a.preset, integrator=a.integrator, threads=a.threads) as ex:
        base = f"http://127.0.0.1:{ex.port}"

        def fetch(window: str, pass_: str) -> float:
            q = {"window": window, "res": a.res, "preset": a.preset, "pass": pass_, "client": "bench"}
            if a.integrator:
                q["integrator"] = a.integrator
            t0 = time.perf_counter()
            with urllib.request.urlopen(f"{base}/api/map.png?{urlencode(q)}", timeout=3600) as r:
                r.read()
                res = r.headers["X-Dicetrace-Res"]
            dt = time.perf_counter() - t0
            print(f"  {window:>32}  {pass_:6}  {res:>7}  {dt:7.3f} s")
            return dt

        t0 = time.perf_counter()
        for warm in (4, 8):  # the single-throw path (up to 16 ICs) and the batch kernel
            q = {"res": warm, "preset": a.preset, "window": "0,0.1,0,0.1"}
            if a.integrator:
                q["integrator"] = a.integrator
            urllib.request.urlopen(f"{base}/api/map.png?{urlencode(q)}", timeout=3600).read()
        print(f"preset {a.preset}, {os.cpu_count()} CPUs; kernel compile or cache load {time.perf_counter() - t0:.2f} s")
        first = fetch(_window("red-sea"), "preview")
        coarse = fetch(_window("red-sea"), "coarse")
        fine = 0.0 if a.no_fine else fetch(_window("red-sea"), "fine")
        zp = fetch(_window("red-sea-2"), "preview")
        zc = fetch(_window("red-sea-2"), "coarse")
        zf = 0.0 if a.no_fine else fetch(_window("red-sea-2"), "fine")
        refined = "" if a.no_fine else f", refined {a.res}×{a.res} {first + coarse + fine:.3f} s"
        zrefined = "" if a.no_fine else f", refined {zp + zc + zf:.3f} s"
        print(f"red sea: first image {first:.3f} s, coarse {first + coarse:.3f} s{refined} after the request; "
              f"after a zoom to red-sea-2: first image {zp:.3f} s, coarse {zp + zc:.3f} s{zrefined} "
              "(the page asks for the passes in turn)")


if __name__ == "__main__":
    main()
