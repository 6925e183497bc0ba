"""``dicetrace explore``: serve the live, zoomable outcome map on 127.0.0.1 and open it in the browser.

Examples::

    dicetrace explore                                   # the red-sea window of the seed slice
    dicetrace explore --window 0.0197,0.0205,0.0177,0.0186 --res 256
    dicetrace explore --slice seed3 --window home --z 0.02 --out scans/  # "save this view as a scan" writes under scans/
    dicetrace explore --no-browser --port 8765          # print the URL only
    dicetrace explore --device cuda                     # the maps on a CUDA GPU (numba-cuda)
    dicetrace explore --preset physical --die 2,2,3 --window home   # the maps of a box (any box, loaded or not)

The view (window, resolution, preset, integrator, γ, dt, z, die, load) is in the page's
URL, so a view can be shared and reopened.  Runs until interrupted (Ctrl-C
stops it at once, even while a map computes).  Maps are shared fairly between
browser tabs, a tab's newer view cancels its older one, and a map that would
take more than --map-budget seconds of computing is refused with a message.
The maps (and saved scans) run on ``--device``, which the page and
``/api/view`` name; a hover's and the viewer's single throws run on the CPU.
The die (``--die X,Y,Z``, ``--load W@X,Y,Z``, as ``simulate`` takes them) is
part of the view: the maps, a hover's and the viewer's throws and a saved scan
are of that die, and the page's header says which die it shows.
Exit code 2 on bad input (a bad option, a port in use, ``--device cuda``
without a GPU), nothing served.
"""

from __future__ import annotations

import os
import sys
import webbrowser
from pathlib import Path
from typing import Optional

import typer

from dicetrace.commands._common import fail, output_dir
from dicetrace.commands.options import DEVICE_HELP, INTEGRATOR_HELP, PRESET_HELP, DieOption, LoadOption, device_or_fail
from dicetrace.explore.server import check_budget, check_host, check_port, check_threads, make_view, serve_forever
from dicetrace.explore.view import ViewError
from dicetrace.extras import require

WINDOW_HELP = "Start window: a name (red-sea, home, party, green-island, ...) or x0,x1,y0,y1."


def register(app: typer.Typer) -> None:
    @app.command("explore")
    def explore_cmd(
        slice_name: str = typer.Option("seed", "--slice", help="Slice: seed, seed3 (3-D, with --z), seed-ortho, seed3-ortho."),
        window: str = typer.Option("red-sea", "--window", help=WINDOW_HELP),
        z: Optional[float] = typer.Option(None, "--z", help="Third coordinate of a 3-D slice (default 0)."),
        res: str = typer.Option("256", "--res", help="Map resolution: N or NX,NY (2 to 1024 per axis)."),
        preset: str = typer.Option("seed", "--preset", help=PRESET_HELP),
        integrator: Optional[str] = typer.Option(None, "--integrator", help=INTEGRATOR_HELP),
        gamma: Optional[float] = typer.Option(None, "--gamma", help="Damping γ, s/cm (default: the preset's)."),
        dt: Optional[float] = typer.Option(None, "--dt", help="Time step, s (default 0.001)."),
        die: DieOption = None,
        load: LoadOption = None,
        host: str = typer.Option("127.0.0.1", "--host", "--bind",
                                 help="Address to listen on (default 127.0.0.1: this machine only)."),
        port: int = typer.Option(0, "--port", help="Port (default: a free one)."),
        no_browser: bool = typer.Option(False, "--no-browser", help="Do not open a browser; print the URL only."),
        out: Optional[Path] = typer.Option(
            None, "--out", help="Folder that 'save this view as a scan' writes into (nothing is written anywhere else; "
            "without it saving is off)."
        ),
        threads: Optional[int] = typer.Option(None, "--threads", help="numba threads per map (default: all)."),
        device: str = typer.Option("cpu", "--device", help=DEVICE_HELP.replace("the throws run", "the maps run")),
        map_budget: Optional[float] = typer.Option(
            None, "--map-budget", help="Seconds of computing one map may take (default 60); a map that would take "
            "longer is refused with a message (fewer pixels or a longer dt)."),
    ) -> None:
        """Explore the outcome map live: zoom recomputes, hover tells the throw, click shows it in Rerun's viewer.

        Needs dicetrace's explore extra (the web server and Rerun's web viewer).
        """
        require("explore", "dicetrace explore")  # before anything else: one line naming the extra
        try:
            view = make_view(slice_name, window, res=res, preset=preset, integrator=integrator, gamma=gamma, dt=dt, z=z,
                             die=die, load=load)
        except ViewError as e:
            fail(f"--{e.param} {e.message}" if e.message.startswith("needs ") else f"--{e.param}: {e.message}")
        for check, value, name in ((check_port, port, "--port"), (check_host, host, "--host"),
                                   (check_threads, threads, "--threads"), (check_budget, map_budget, "--map-budget")):
            try:
                check(value, name)
            except ValueError as e:
                fail(str(e))
        label = device_or_fail(device)  # before anything listens
        if out is not None:
            out = output_dir(out, "--out")
            out.mkdir(parents=True, exist_ok=True)

        def ready(url: str) -> None:
            print(f"dicetrace explore: serving {url}  (maps on {label}; Ctrl-C to stop)", flush=True)
            if not no_browser:
                webbrowser.open(url)

        try:
            serve_forever(view, host=host, port=port, out=out, threads=threads, map_budget_s=map_budget, on_ready=ready,
                          device="cpu" if label == "cpu" else "cuda")
        except OSError as e:
            fail(f"--host {host} --port {port}: cannot listen there: {e.strerror or e}")
        except KeyboardInterrupt:
            # Ctrl-C: the server has stopped (every map cancelled, nothing half-written: a save in progress is a
            # resumable scan folder).  A kernel call can still be running on a worker thread and the interpreter's
            # own teardown of numba's compiled code takes a second or more, so end the process now.
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(0)
