"""``dicetrace accuracy`` (work-precision study) and ``dicetrace stability`` (stable-step map).

Both write CSV, PNG and a Markdown summary into ``--out`` (default
``analysis/accuracy``) and print where.  ``--quick`` is the CI size (under a
minute once the kernels are compiled).  Bad input: one line on stderr,
exit code 2.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Optional

import typer

from dicetrace.commands._common import fail

DEFAULT_OUT = Path("analysis/accuracy")


def _names(text: str | None, allowed, what: str):
    if text is None:
        return None
    vals = tuple(v.strip() for v in text.split(",") if v.strip())
    bad = [v for v in vals if v not in allowed]
    if bad or not vals:
        fail(f"unknown {what} {', '.join(bad) or repr(text)} (choose from {', '.join(allowed)})")
    return vals


def _out_dir(out: Path) -> Path:
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        fail(f"cannot create output folder {str(out)!r}: {e.strerror}")
    if not out.is_dir():
        fail(f"output path {str(out)!r} is not a folder")
    return out


def _command_line() -> str:
    return "dicetrace " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:] else "dicetrace accuracy"


def _say(quiet: bool):
    if quiet:
        return None
    return lambda msg: print(msg, file=sys.stderr, flush=True)


def register(app: typer.Typer) -> None:
    @app.command("accuracy")
    def accuracy_cmd(
        window: str = typer.Option("zoom-out", "--window", help="Window of the seed slice: a name (home, zoom-out, ...) or x0,x1,y0,y1."),
        n: Optional[int] = typer.Option(None, "--n", help="ICs in the seeded sample (default 300; --quick: 12)."),
        seed: int = typer.Option(0, "--seed", help="Seed of the IC sample and the perturbations."),
        quick: bool = typer.Option(False, "--quick", help="CI size: few ICs, two steps per integrator, coarser reference."),
        presets: Optional[str] = typer.Option(None, "--presets", help="Comma-separated presets (default seed,physical)."),
        integrators: Optional[str] = typer.Option(None, "--integrator", "--integrators", help="Comma-separated integrators (default: all)."),
        threads: int = typer.Option(2, "--threads", help="numba threads for the untimed reference runs (timed runs use one)."),
        out: Path = typer.Option(DEFAULT_OUT, "--out", help="Output folder: study.csv, orders.csv, reference.csv, work_precision.png, summary.md."),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress lines."),
    ) -> None:
        """Work-precision study: outcome agreement, chaos floor, first-impact error, biases and CPU time per integrator and dt."""
        from dicetrace import accuracy as acc
        from dicetrace.ics import get_window
        from dicetrace.params import INTEGRATORS, PRESETS

        try:
            get_window(window, 2)
        except ValueError as e:
            fail(str(e))
        if n is not None and n < 2:
            fail(f"--n must be at least 2, got {n}")
        if threads < 1:
            fail(f"--threads must be >= 1, got {threads}")
        ps = _names(presets, tuple(PRESETS), "preset") or acc.PRESETS
        integs = _names(integrators, tuple(INTEGRATORS), "integrator")
        out = _out_dir(out)
        res = acc.study(window=window, n=n, seed=seed, quick=quick, presets=ps, integrators=integs,
                        threads=threads, progress=_say(quiet))
        paths = acc.write_study(res, out, _command_line())
        if not quiet:
            print(paths["summary"].read_text())
        for key in ("csv", "orders", "reference", "png", "summary"):
            print(f"wrote {paths[key]}")

    @app.command("stability")
    def stability_cmd(
        quick: bool = typer.Option(False, "--quick", help="CI size: two stiffnesses, five corpus ICs, three bisections."),
        presets: Optional[str] = typer.Option(None, "--presets", help="Comma-separated presets (default seed,physical)."),
        integrators: Optional[str] = typer.Option(None, "--integrator", "--integrators", help="Comma-separated integrators (default: all)."),
        k_values: Optional[str] = typer.Option(None, "--k", help="Comma-separated stiffnesses k (1/s²; default 5e5 … 5e7)."),
        out: Path = typer.Option(DEFAULT_OUT, "--out", help="Output folder: stability.csv, stability.png, stability.md."),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress lines."),
    ) -> None:
        """Map the stable region: largest stable dt per integrator across k and an extreme corpus, vs the linear bounds and dt auto."""
        from dicetrace import accuracy as acc
        from dicetrace.commands._common import parse_floats
        from dicetrace.params import INTEGRATORS, PRESETS

        ps = _names(presets, tuple(PRESETS), "preset") or acc.PRESETS
        integs = _names(integrators, tuple(INTEGRATORS), "integrator")
        ks = None
        if k_values is not None:
            ks = parse_floats(k_values, None, "--k")
            if any(k <= 0 for k in ks):
                fail(f"--k values must be > 0, got {k_values!r}")
        out = _out_dir(out)
        rows = acc.stability_map(quick=quick, presets=ps, integrators=integs, k_values=ks, progress=_say(quiet))
        paths = acc.write_stability(rows, out, _command_line())
        if not quiet:
            print(paths["summary"].read_text())
        for key in ("csv", "png", "summary"):
            print(f"wrote {paths[key]}")
