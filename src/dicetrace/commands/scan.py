"""``dicetrace scan``: colour a slice of IC space by outcome, streamed to Parquet.

Examples::

    dicetrace scan --slice seed --window red-sea --res 400 --out scans/red-sea
    dicetrace scan --window 0,0.1,0,0.1 --res 21 --out scans/home
    dicetrace scan --slice seed3 --window home --z 0,0.1 --res 200,200,50 --out scans/cube
    dicetrace scan --sample sobol --n 100000 --box 0,20,0,20 --out scans/sobol
    dicetrace scan --points writeup_points.csv --out scans/named
    dicetrace scan ... --dask                      # a local Dask cluster
    dicetrace scan ... --scheduler tcp://host:8786 # an existing one

The output folder is a Parquet dataset (``_scan.json`` + ``part-*.parquet``),
written chunk by chunk: re-running the same command resumes; a different
definition against the folder is refused.  ``--png`` draws the outcome map,
``--rrd`` writes the interactive scan map for the Rerun viewer.

Exit codes: 0 done; 2 bad input (or a folder holding another scan); 130
interrupted (re-run to resume).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path
from typing import List, Optional

import numpy as np
import typer

from dicetrace.commands._common import fail, parse_floats
from dicetrace.commands.simulate import INTEGRATOR_HELP, TOL_HELP

SLICE_HELP = "Slice of IC space: seed (the writeup's 2-D), seed3 (3-D), seed-ortho, seed3-ortho (Gram–Schmidt)."
WINDOW_HELP = (
    "Window: a name (home, zoom-out, more-out, most-out, red-sea, red-sea-2, party, green-island) "
    "or x0,x1,y0,y1[,z0,z1]."
)
RES_HELP = "Grid points per axis: N (every axis), NX,NY or NX,NY,NZ (the program's formula x0+(p-1)/(n-1)(x1-x0))."


def _parse_res(text: str, ndim: int) -> tuple[int, ...]:
    parts = [p.strip() for p in text.split(",")]
    try:
        vals = [int(p) for p in parts]
    except ValueError:
        fail(f"--res must be integers N or NX,NY[,NZ], got {text!r}")
    if len(vals) == 1:
        vals = vals * ndim
    if len(vals) != ndim:
        fail(f"--res needs {ndim} numbers for a {ndim}-D slice, got {len(vals)} in {text!r}")
    if any(v < 1 for v in vals):
        fail(f"--res must be >= 1 on every axis, got {text!r}")
    return tuple(vals)


def _read_points(path: Path, ndim: int) -> np.ndarray:
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        fail(f"cannot read --points file {str(path)!r}: {e.strerror}")
    names = ["x", "y", "z"][:ndim]
    if not rows or any(n not in rows[0] for n in names):
        fail(f"--points file {str(path)!r} needs columns {', '.join(names)} (a {ndim}-D slice)")
    try:
        pts = np.array([[float(r[n]) for n in names] for r in rows])
    except ValueError:
        fail(f"--points file {str(path)!r} has a non-numeric coordinate")
    if not np.all(np.isfinite(pts)):
        fail(f"--points file {str(path)!r} has a non-finite coordinate")
    return pts


def build_slice(slice_name: str, origin: Optional[str], dirs: Optional[List[str]]):
    """A named slice, or a custom one from --origin and --dir (1 to 3)."""
    from dicetrace.ics import SLICES, Slice

    if origin is not None or dirs:
        if origin is None or not dirs:
            fail("a custom slice needs --origin VX,VY,VZ,LX,LY,LZ and 1 to 3 --dir (6 numbers each)")
        o = parse_floats(origin, 6, "--origin")
        ds = [parse_floats(d, 6, "--dir") for d in dirs]
        if len(ds) > 3:
            fail(f"a slice has at most 3 directions, got {len(ds)} --dir")
        try:
            return Slice("custom", tuple(o), tuple(tuple(d) for d in ds))
        except ValueError as e:
            fail(str(e))
    if slice_name not in SLICES:
        fail(f"unknown slice {slice_name!r} (choose from {', '.join(SLICES)})")
    return SLICES[slice_name]


def build_space(sl, window, z, res, sample, n, box, seed, points):
    """The IC space from the options (grid, sample or points), or a one-line failure."""
    from dicetrace.ics import Grid, Points, Sample, get_window

    given = [name for name, v in (("--window/--res", window or res), ("--sample", sample), ("--points", points)) if v]
    if len(given) > 1:
        fail(f"give one IC space: {' or '.join(given)}, not several")
    try:
        if points is not None:
            return Points(sl, _read_points(points, sl.ndim))
        if sample is not None:
            if n is None:
                fail("--sample needs --n N (how many ICs)")
            if box is None:
                fail("--sample needs --box x0,x1,y0,y1[,z0,z1] (or a window name)")
            zr = parse_floats(z, 2, "--z") if z is not None else None
            return Sample(sl, get_window(box, sl.ndim, zr), n, sample, seed)
        if window is None:
            fail("give --window NAME or x0,x1,y0,y1[,z0,z1] (with --res), or --sample, or --points")
        if res is None:
            fail("--window needs --res N (points per axis), e.g. --res 400 or --res 200,200,50")
        zr = parse_floats(z, 2, "--z") if z is not None else None
        return Grid(sl, get_window(window, sl.ndim, zr), _parse_res(res, sl.ndim))
    except ValueError as e:
        fail(str(e))


def parse_overrides(preset_name: str, items: List[str]) -> dict:
    """``--set NAME=VALUE`` items as Preset field overrides (numbers, booleans or words)."""
    from dataclasses import fields

    from dicetrace.commands.simulate import preset_or_fail

    if not items:
        return {}
    preset = preset_or_fail(preset_name)
    names = {f.name: f for f in fields(preset) if f.name != "name"}
    changes = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or key not in names:
            fail(f"--set needs NAME=VALUE with NAME one of {', '.join(sorted(names))}, got {item!r}")
        current = getattr(preset, key)
        text = text.strip()
        if isinstance(current, bool):
            if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                fail(f"--set {key} needs true or false, got {text!r}")
            changes[key] = text.lower() in ("true", "1", "yes")
        elif isinstance(current, (int, float)):
            try:
                changes[key] = float(text)
            except ValueError:
                fail(f"--set {key} needs a number, got {text!r}")
        else:
            changes[key] = text
    return changes


def _existing_chunk(out: Path) -> int | None:
    import json

    from dicetrace.scan import MANIFEST

    try:
        return int(json.loads((out / MANIFEST).read_text())["definition"]["chunk"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def register(app: typer.Typer) -> None:
    @app.command("scan")
    def scan_cmd(
        out: Path = typer.Option(..., "--out", help="Output folder (a Parquet dataset; re-run to resume)."),
        slice_name: str = typer.Option("seed", "--slice", help=SLICE_HELP),
        window: Optional[str] = typer.Option(None, "--window", help=WINDOW_HELP),
        z: Optional[str] = typer.Option(None, "--z", help="Z0,Z1: the z range with a named window on a 3-D slice."),
        res: Optional[str] = typer.Option(None, "--res", help=RES_HELP),
        sample: Optional[str] = typer.Option(None, "--sample", help="random or sobol: N points in --box instead of a grid."),
        n: Optional[int] = typer.Option(None, "--n", help="Number of sample points (--sample)."),
        box: Optional[str] = typer.Option(None, "--box", help="Sample box: a window name or x0,x1,y0,y1[,z0,z1]."),
        seed: int = typer.Option(0, "--seed", help="Seed of the random or scrambled Sobol sample."),
        points: Optional[Path] = typer.Option(None, "--points", help="CSV of slice coordinates (columns x,y[,z])."),
        origin: Optional[str] = typer.Option(None, "--origin", help="Custom slice origin VX,VY,VZ,LX,LY,LZ."),
        dirs: Optional[List[str]] = typer.Option(None, "--dir", help="Custom slice direction (6 numbers; 1 to 3 times)."),
        preset: str = typer.Option("seed", "--preset", help="Model preset: seed (the 2019 program, bit for bit) or physical."),
        integrator: Optional[str] = typer.Option(None, "--integrator", help=INTEGRATOR_HELP),
        dt: Optional[str] = typer.Option(None, "--dt", help="Time step, s (default 0.001), or 'auto' (chosen from the stiffness k for a 300 cm/s impact; refused when no step fits)."),
        t_max: Optional[str] = typer.Option(None, "--t-max", help="Time cap, s (default 60)."),
        tol: Optional[str] = typer.Option(None, "--tol", help=TOL_HELP),
        sets: Optional[List[str]] = typer.Option(
            None, "--set", help="Override a preset parameter, NAME=VALUE (e.g. gamma=0.01, mu=0.6, k=1e6); repeatable."
        ),
        chunk: Optional[int] = typer.Option(None, "--chunk", help="ICs per chunk file / Dask task (default 8192)."),
        threads: Optional[int] = typer.Option(None, "--threads", help="numba threads (default: all cores)."),
        dask: bool = typer.Option(False, "--dask", help="Run the chunks on a local Dask cluster."),
        scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Run the chunks on the Dask scheduler at ADDRESS."),
        workers: Optional[int] = typer.Option(None, "--workers", help="Worker processes of the --dask cluster (default: cores)."),
        max_chunks: Optional[int] = typer.Option(None, "--max-chunks", help="Stop after this many new chunks (resumable)."),
        rrd: Optional[Path] = typer.Option(None, "--rrd", help="Also write the scan map for the Rerun viewer (.rrd)."),
        png: Optional[Path] = typer.Option(None, "--png", help="Also draw the outcome map (2-D grid scans) into a PNG."),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar or summary."),
    ) -> None:
        """Scan a slice (grid), a sample or a list of points of IC space; one row per IC."""
        from dicetrace.commands.simulate import build_config
        from dicetrace.scan import DEFAULT_CHUNK, ScanDefinition, ScanMismatchError, outcome_counts, scan

        sl = build_slice(slice_name, origin, dirs)
        space = build_space(sl, window, z, res, sample, n, box, seed, points)
        cfg = build_config(preset, integrator, dt, t_max, tol=tol, overrides=parse_overrides(preset, sets or []))
        if chunk is not None and chunk < 1:
            fail(f"--chunk must be >= 1, got {chunk}")
        if threads is not None and threads < 1:
            fail(f"--threads must be >= 1, got {threads}")
        if dask and scheduler:
            fail("give --dask (a local cluster) or --scheduler ADDRESS, not both")
        if png is not None and (space.kind != "grid" or space.ndim < 2):
            fail("--png draws 2-D and 3-D grid scans only (use --rrd for samples, points and 1-D slices)")
        if chunk is None:  # resuming: keep the folder's chunk size
            chunk = _existing_chunk(out) or DEFAULT_CHUNK
        defn = ScanDefinition(space, cfg, chunk)
        if out.exists() and not out.is_dir():
            fail(f"--out {str(out)!r} is a file, expected a folder")
        try:
            report = scan(
                defn, out, threads=threads, progress=not quiet,
                dask=scheduler or (True if dask else None), n_workers=workers, max_chunks=max_chunks,
            )
        except (ScanMismatchError, FileExistsError) as e:
            fail(str(e))
        except KeyboardInterrupt:
            print(f"dicetrace: interrupted; finished chunks are kept in {str(out)!r}: re-run the same command to resume",
                  file=sys.stderr)
            raise
        if not quiet:
            done = report.chunks_skipped + report.chunks_computed
            msg = (f"{report.n_ics:,} ICs in {report.n_chunks} chunks → {out}  "
                   f"({report.chunks_computed} computed, {report.chunks_skipped} already there; "
                   f"{report.ics_computed:,} ICs in {report.wall_s:.1f} s, {report.rate_ics_s:,.0f} ICs/s)")
            print(msg, file=sys.stderr)
            if done < report.n_chunks:
                print(f"{report.n_chunks - done} chunks left: re-run the same command to finish", file=sys.stderr)
            else:
                counts = outcome_counts(out)
                total = sum(counts.values())
                names = {-1: "not settled", 0: "undefined"}
                parts = [f"{names.get(v, f'face {v}')}: {c / total:.1%}" for v, c in counts.items()]
                print("outcomes: " + ", ".join(parts), file=sys.stderr)
        if png is not None:
            from dicetrace.scan.maps import outcome_png

            outcome_png(out, png)
            if not quiet:
                print(f"outcome map → {png}", file=sys.stderr)
        if rrd is not None:
            from dicetrace.scan.maps import write_scan_rrd

            write_scan_rrd(out, rrd)
            if not quiet:
                print(f"scan map → {rrd} (open with: rerun {rrd})", file=sys.stderr)
