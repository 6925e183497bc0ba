"""``dicetrace scan``: colour a slice of IC space by outcome, streamed to Parquet.

Examples::

    dicetrace scan --slice seed --window red-sea --res 400 --out scans/red-sea
    dicetrace scan --window 0,0.1,0,0.1 --res 21 --out scans/home
    dicetrace scan --slice seed3 --window home --z 0,0.1 --res 200,200,50 --out scans/cube
    dicetrace scan --sample sobol --n 100000 --box 0,20,0,20 --out scans/sobol
    dicetrace scan --points writeup_points.csv --out scans/named
    dicetrace scan ... --dask                      # a local Dask cluster
    dicetrace scan ... --scheduler tcp://host:8786 # an existing one
    dicetrace scan ... --device cuda               # on a CUDA GPU (numba-cuda)
    dicetrace scan --preset physical ... --events  # exact contact events (a contact_times_s column)
    dicetrace scan --preset physical --die 2,2,3 --window home --res 64 --out scans/box  # any box
    dicetrace scan --throw casual --n 100000 --seed 1 --die 2,2,3 --out scans/hand  # hand throws, each its own pose
    dicetrace scan --throws out/throws/rolls.parquet --out scans/table               # the throws of a table

The die is any box, loaded or not (``--die X,Y,Z``, ``--load W@X,Y,Z``, as
``simulate`` takes them; the same as ``--set half_extents_cm=...`` with half
the sides); it is part of the scan's definition, and every chunk's metadata and
the manifest say it (``"die"``: sides, half-extents, load, centre of mass).
``--throw MODEL --n N --seed S`` (a hand-throw model of :mod:`dicetrace.throws`)
and ``--throws FILE`` (a throw table: ``dicetrace throw``'s Parquet, or a CSV
with the columns vx, vy, vz, Lx, Ly, Lz, qx, qy, qz, qw, z0_cm) scan full
starting states instead of a slice: each throw from its own orientation and
height (:mod:`dicetrace.scan.poses`), on the CPU; the rows add
``qx, qy, qz, qw, z0_cm``, and ``dicetrace record --rolls OUT --ic-id N``
replays any row exactly.

The output folder holds the rolls table ``rolls/part-*.parquet``, written
chunk by chunk, and the manifest ``_scan.parquet`` (no rows; the scan's
definition and chunk log in its metadata): any Parquet reader reads ``OUT/``
as it is (``OUT/rolls/`` too, even while a scan writes); re-running the same command
resumes (each finished chunk checked against its checksum and the definition in its own
metadata; one not logged yet adopted once its content is the chunk's; anything that is
not the scan's refused by name); a different definition against the folder is refused
(the definitions compared by value, the field that differs named), and so is
resuming on another ``--device`` than the scan started on (the definition
and every chunk's metadata record the device: ``cpu`` or ``cuda: <GPU name>``).  ``--png`` draws the outcome map,
``--rrd`` writes the interactive scan map for the Rerun viewer.

Every option and output (``--out``, ``--png``, ``--rrd``) is checked before
any work (``--device cuda`` without a GPU too: on a ``--scheduler`` cluster,
by a worker); a large run says its estimated time and disk first (the time from
the warm kernels' throughput on a probe, at the machine's present load: a
first run's compile is not counted; the probe's throws' contact sets count in
the disk and memory), refuses what the disk or the memory cannot hold, and
asks for ``--yes`` beyond ``MAX_UNCONFIRMED_S`` (measured twice before it
refuses).  One writer per folder: a second scan into a folder
being written waits ``--wait`` seconds for it, then refuses.

Exit codes: 0 done; 1 with ``--strict`` when an IC ended in a numerical
failure (non_finite, blow_up); 2 bad input (or a folder holding another
scan, or being written by one); 130 interrupted (re-run to resume; a run
interrupted or failing before its first chunk leaves no scan in a new
folder).  What the scan says on standard error decides nothing: closed or
full, the data is written and the exit code is the same.
"""

from __future__ import annotations

import csv
import math
import sys
from dataclasses import fields, replace
from pathlib import Path
from typing import List, Optional

import numpy as np
import typer

from dicetrace.commands._common import (
    EXIT_NUMERICAL_FAILURE,
    fail,
    output_dir,
    output_file,
    parse_floats,
    say,
    say_interrupted,
    stderr_is_terminal,
)
from dicetrace.commands.options import (
    DEVICE_HELP,
    DieOption,
    LoadOption,
    body_overrides,
    die_options,
    die_text,
    plain_body,
    INTEGRATOR_HELP,
    PRESET_HELP,
    TOL_GROWTH_HELP,
    TOL_HELP,
    ScanEventsOption,
    build_config,
    config_errors,
    device_or_fail,
    events_or_fail,
    fmt_num,
    preset_or_fail,
)
from dicetrace.compile_clock import rate_text
from dicetrace.devices import DeviceError, check_device
from dicetrace.extras import require
from dicetrace.ics import SLICES, Grid, Points, Sample, Slice
from dicetrace.memory import available_memory
from dicetrace.sinks._common import Staging, human_bytes
from dicetrace.status import Status
from dicetrace.windows import get_res, get_window

SLICE_HELP = ("Slice of IC space: seed (the writeup's 2-D; the default), seed3 (3-D), seed-ortho, seed3-ortho "
              "(Gram–Schmidt).")
THROW_HELP = ("Scan hand throws instead of a slice: N (--n) throws drawn from the model casual, gentle or vigorous "
              "(dicetrace.throws; seeded by --seed), each from its own orientation and height; CPU only.")
THROWS_HELP = ("Scan the throws of a table instead of a slice: a Parquet file (dicetrace throw's rolls.parquet) or a "
               "CSV with the columns vx, vy, vz, Lx, Ly, Lz, qx, qy, qz, qw, z0_cm (L in the preset's convention), each throw "
               "from its own orientation and height; CPU only.")
WINDOW_HELP = (
    "Window: a name (home, zoom-out, more-out, most-out, red-sea, red-sea-2, party, green-island) "
    "or x0,x1,y0,y1[,z0,z1] with x1 > x0, y1 > y0, z1 > z0 (an axis of one grid point may be a single value)."
)
RES_HELP = "Grid points per axis: N (every axis), NX,NY or NX,NY,NZ (the program's formula x0 + (x1 - x0)(p - 1)/(n - 1))."
#: A run estimated to take longer than this (s) needs --yes.
MAX_UNCONFIRMED_S = 3600.0
#: A run estimated to take longer than this (s), or to write more than LARGE_SCAN_BYTES, says so first.
LARGE_SCAN_S = 60.0
LARGE_SCAN_BYTES = 1 << 30


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
            fail(f"--dir: {e}")
    if slice_name not in SLICES:
        fail(f"--slice: unknown slice {slice_name!r} (choose from {', '.join(SLICES)})")
    return SLICES[slice_name]


def build_space(sl, window, z, res, sample, n, box, seed, points, throw=None):
    """The IC space from the options (grid, sample, points or hand throws), or a one-line failure naming the option.

    Windows, boxes, z ranges and resolutions are read and checked by the one
    parser of each (:func:`dicetrace.windows.get_window`, ``get_res``); the
    spaces check the rest; what they refuse names its option (``config_errors``).
    ``throw``: the name of a hand-throw model (``--throw``): ``--n`` throws of it,
    seeded by ``--seed``, on no slice.
    """
    given = [name for name, v in (("--window/--res", window or res), ("--sample", sample), ("--points", points),
                                  ("--throw", throw)) if v]
    if len(given) > 1:
        fail(f"give one IC space: {' or '.join(given)}, not several")
    if sample is None and throw is None:  # an option that would be ignored is refused: it says the user meant something else
        for name, v in (("--n", n), ("--box", box), ("--seed", seed)):
            if v is not None:
                fail(f"{name} goes with --sample (random or sobol) or --throw (a hand-throw model), neither is given")
    if throw is not None:
        from dicetrace.scan.poses import HandThrows  # lazy: keeps `dicetrace --help` fast

        for name, v in (("--box", box), ("--z", z)):
            if v is not None:
                fail(f"{name} goes with a slice, not with --throw (hand throws lie on no slice)")
        if n is None:
            fail("--throw needs --n N (how many throws)")
        with config_errors(throw="--throw"):
            return HandThrows(throw, n, 0 if seed is None else seed)
    if points is not None and z is not None:
        fail("--z goes with a named --window or --box on a 3-D slice, not with --points")
    if z is not None and sl.ndim != 3:
        fail(f"--z: the slice is {sl.ndim}-D: a z range applies only to a 3-D slice (seed3, seed3-ortho)")
    if points is not None:
        try:
            return Points(sl, _read_points(points, sl.ndim))
        except ValueError as e:
            fail(f"--points {str(points)!r}: {e}")
    if sample is not None:
        if n is None:
            fail("--sample needs --n N (how many ICs)")
        if box is None:
            fail("--sample needs --box x0,x1,y0,y1[,z0,z1] (or a window name)")
        with config_errors(window="--box"):
            return Sample(sl, get_window(box, sl.ndim, z), n, sample, 0 if seed is None else seed)
    if window is None:
        fail("give --window NAME or x0,x1,y0,y1[,z0,z1] (with --res), or --sample, --points, --throw or --throws")
    if res is None:
        fail("--window needs --res N (points per axis), e.g. --res 400 or --res 200,200,50")
    with config_errors():
        shape = get_res(res, sl.ndim)
        return Grid(sl, get_window(window, sl.ndim, z, points=shape), shape)


def throws_space(path: Path, l_convention: str, given: dict):
    """The throws of the table ``--throws FILE`` (:func:`dicetrace.scan.poses.read_throw_table`), or a one-line
    failure: a file that is no throw table, or another IC space given beside it (``given``: option → value)."""
    from dicetrace.scan.poses import read_throw_table  # lazy: keeps `dicetrace --help` fast

    others = [name for name, v in given.items() if v is not None]
    if others:
        fail(f"--throws gives the throws: drop {', '.join(others)}")
    try:
        return read_throw_table(path, l_convention)
    except ValueError as e:
        fail(f"--throws {str(path)!r}: {e}")


def die_overrides(preset, die: str | None, load: str | None, sets: dict) -> tuple[dict, dict]:
    """The preset fields of ``--set`` and of ``--die``/``--load`` together, and the option each body field came from
    (for a refusal's line); one line, exit 2, when both give the same field."""
    body = body_overrides(die, load)
    for field, option in (("half_extents_cm", "--die"), ("load_fraction", "--load"), ("load_cm", "--load")):
        if field in body and field in sets:
            fail(f"{option} and --set {field} both give the die: give it once ({option}; --set {field}= is the same "
                 "field, half the sides for half_extents_cm)")
    renamed = {field: "--set" for field in ("half_extents_cm", "load_fraction", "load_cm") if field in sets}
    return {**sets, **body}, renamed


def parse_overrides(preset, items: List[str]) -> dict:
    """``--set NAME=VALUE`` items as overrides of the Preset ``preset``'s fields (numbers, booleans or words)."""
    if not items:
        return {}
    names = {f.name: f for f in fields(preset) if f.name != "name"}
    changes, given = {}, {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or key not in names:
            fail(f"--set needs NAME=VALUE with NAME one of {', '.join(sorted(names))}, got {item!r}")
        current = getattr(preset, key)
        text = text.strip()
        if key in given:  # the last one would win, silently
            fail(f"--set {key} given twice ({key}={given[key]}, {key}={text}): give each parameter once")
        given[key] = text
        if isinstance(current, bool):
            if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                fail(f"--set {key} needs true or false, got {text!r}")
            changes[key] = text.lower() in ("true", "1", "yes")
        elif isinstance(current, (int, float)):
            try:
                changes[key] = float(text)
            except ValueError:
                fail(f"--set {key} needs a number, got {text!r}")
        elif current is None or isinstance(current, tuple):  # an optional number, or a triple (half_extents_cm, ...)
            try:
                values = tuple(float(t) for t in text.split(",")) if text.lower() != "none" else None
            except ValueError:
                fail(f"--set {key} needs a number or numbers X,Y,Z (or none), got {text!r}")
            changes[key] = values if values is None or len(values) > 1 else values[0]
        else:
            changes[key] = text
    return changes


def _existing_chunk(out: Path) -> int | None:
    from dicetrace.scan import read_manifest  # lazy: keeps `dicetrace --help` fast (imports numba)

    try:
        return int(read_manifest(out)["definition"]["chunk"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _status_summary(out: Path, quiet: bool) -> bool:
    """Print the outcome and status counts of a finished scan (the failure line even when quiet); True if any IC failed."""
    from dicetrace.scan.read import outcome_counts, status_counts  # lazy: keeps `dicetrace --help` fast (imports numba)

    statuses = status_counts(out)
    total = sum(statuses.values())
    if not total:
        return False
    if not quiet:
        counts = outcome_counts(out)
        names = {-1: "not settled", 0: "undefined"}
        parts = [f"{names.get(v, f'face {v}')}: {c / total:.1%}" for v, c in counts.items()]
        say("outcomes: " + ", ".join(parts))
        say("statuses: " + ", ".join(f"{k}: {c:,} ({c / total:.1%})" for k, c in
                                     sorted(statuses.items(), key=lambda kv: -kv[1])))
    failed = {k: c for k, c in statuses.items() if Status.from_label(k).failed}
    if failed:
        first = Status.from_label(max(failed, key=failed.get))
        detail = ", ".join(f"{k}: {c:,}" for k, c in sorted(failed.items()))
        say(f"dicetrace: numerical failure: {sum(failed.values()):,} of {total:,} ICs failed ({detail}): "
            f"{first.advice}")
    return bool(failed)


def _check_fits(est, defn, out: Path, maps, local_workers) -> None:
    """Refuse (one line) a run whose chunk in flight, maps or local Dask workers would not fit in memory, or whose
    new chunks would not fit on the disk, by the estimate ``est``."""
    from dicetrace.scan.estimate import (  # lazy: keeps `dicetrace --help` fast (imports numba)
        DASK_WORKER_MEMORY,
        MAP_MEMORY_BASE,
        MAP_MEMORY_PER_IC,
        TYPICAL_SETS,
    )

    avail = available_memory()
    heavy = est.sets_per_ic is not None and est.sets_per_ic > TYPICAL_SETS
    probed = f" ({est.sets_per_ic:,.0f} contact sets per IC on a probe)" if heavy else ""
    if avail is not None:
        if est.ic_memory * 2 > avail:
            fail(f"--t-max {fmt_num(defn.config.numerics.t_max_s)}: one IC's row needs about "
                 f"{human_bytes(est.ic_memory)} of memory{probed}, {human_bytes(avail)} available: use a shorter "
                 "--t-max" + (" or scan without --events" if defn.events else ""))
        if est.chunk_memory * 2 > avail:
            ics = min(defn.chunk, defn.size)
            fail(f"--chunk {defn.chunk:,}: one chunk{'' if ics == defn.chunk else f' ({ics:,} ICs)'} needs about "
                 f"{human_bytes(est.chunk_memory)} of memory{probed}, {human_bytes(avail)} available: use a smaller "
                 "--chunk")
        if local_workers is not None:
            need = local_workers * (DASK_WORKER_MEMORY + est.chunk_memory)
            if need > avail:
                fail(f"--workers {local_workers:,}: a local Dask cluster of {local_workers:,} worker process(es) needs "
                     f"about {human_bytes(need)} of memory, {human_bytes(avail)} available: use fewer --workers")
        need = MAP_MEMORY_BASE + defn.size * MAP_MEMORY_PER_IC
        if maps and need > avail:
            fail(f"{' and '.join(maps)}: drawing the map of {defn.size:,} ICs needs about {human_bytes(need)} of "
                 f"memory, {human_bytes(avail)} available: scan without {' and '.join(maps)}, or a smaller grid")
    if est.free_bytes is not None and est.bytes > est.free_bytes:
        fail(f"--out {str(out)!r}: this run writes about {human_bytes(est.bytes)} ({est.ics_todo:,} ICs{probed}), "
             f"only {human_bytes(est.free_bytes)} free there: free space, or scan in parts with --max-chunks N")


def _check_run_size(defn, out: Path, threads, max_chunks, yes: bool, quiet: bool, dask_workers, *,
                    maps=(), local_workers=None) -> None:
    """Check the run's size before any work: memory (a chunk, the maps, local Dask workers) and disk first, then
    the time (calibrated: refused beyond MAX_UNCONFIRMED_S without --yes); say it when large.

    The calibrating probe also counts the throws' contact sets: memory and disk are checked again with what they
    take (a throw that never settles can record millions).  ``maps``: the map options given (``--png``,
    ``--rrd``: drawn from the whole scan in memory); ``local_workers``: the processes of a local ``--dask``
    cluster (None: no local cluster).
    """
    from dicetrace.scan.estimate import estimate_scan, human_seconds  # lazy: keeps `dicetrace --help` fast

    quick = estimate_scan(defn, out, threads=dask_workers or threads, max_chunks=max_chunks, calibrate=False)
    _check_fits(quick, defn, out, maps, local_workers)
    est = estimate_scan(defn, out, threads=dask_workers or threads, max_chunks=max_chunks)
    if est.sets_per_ic is not None:
        _check_fits(est, defn, out, maps, local_workers)
    if est.seconds is not None and est.seconds > MAX_UNCONFIRMED_S and not yes:
        # refuse only on an estimate that holds: measure once more (a busy moment can slow one measure down)
        again = estimate_scan(defn, out, threads=dask_workers or threads, max_chunks=max_chunks)
        if again.seconds is not None and again.seconds < est.seconds:
            est = again
    if est.seconds is not None and est.seconds > MAX_UNCONFIRMED_S and not yes:
        fail(f"this scan would take {est.describe()}, more than {human_seconds(MAX_UNCONFIRMED_S)}: "
             "confirm with --yes, or scan in parts with --max-chunks N (re-run to resume)")
    if not quiet and ((est.seconds or 0) > LARGE_SCAN_S or est.bytes > LARGE_SCAN_BYTES):
        say(f"dicetrace: scan: {est.describe()}")


def _other_die(out: Path, defn) -> str | None:
    """The line that refuses resuming the scan in ``out`` with another die than its own (None: the same die, or no
    scan there that can be read)."""
    from dicetrace.scan import read_manifest  # lazy: keeps `dicetrace --help` fast (imports numba)
    from dicetrace.scan.definition import config_from_dict

    try:
        have = plain_body(config_from_dict(read_manifest(out)["definition"]["config"]).preset)
    except (OSError, ValueError, KeyError, TypeError):
        return None
    want = defn.config.preset
    if have.body == want.body:
        return None
    option = "--die" if have.body.half_extents_cm != want.body.half_extents_cm else "--load"
    return (f"{option}: {str(out)!r} holds a scan of another die ({die_text(have)}; this run: {die_text(want)}): "
            f"resume it with {die_options(have)}, or use another --out folder")


def _check_out(out: Path, defn) -> None:
    """Refuse (one line) a folder the scan ``defn`` cannot go into: another scan's (another die's named by its
    option, ``--die`` or ``--load``), the same run on another device (``--device``), or files that are not a scan."""
    # lazy: keeps `dicetrace --help` fast (imports numba)
    from dicetrace.scan import DeviceMismatchError, ScanMismatchError
    from dicetrace.scan.folder import ScanBusyError, check_folder

    try:
        check_folder(out, defn)
    except DeviceMismatchError as e:
        fail(f"--device: {e}")
    except ScanMismatchError as e:
        fail(_other_die(out, defn) or f"--out: {e}")
    except (FileExistsError, ScanBusyError) as e:
        fail(f"--out: {e}")


def register(app: typer.Typer) -> None:
    @app.command("scan")
    def scan_cmd(
        out: Path = typer.Option(..., "--out", help="Output folder: a Parquet dataset, one row per IC, that any reader reads as it is (re-run to resume)."),
        slice_name: Optional[str] = typer.Option(None, "--slice", help=SLICE_HELP),
        window: Optional[str] = typer.Option(None, "--window", help=WINDOW_HELP),
        z: Optional[str] = typer.Option(None, "--z", help="Z0,Z1: the z range with a named window on a 3-D slice (z1 > z0, or z1 = z0 with one z point)."),
        res: Optional[str] = typer.Option(None, "--res", help=RES_HELP),
        sample: Optional[str] = typer.Option(None, "--sample", help="random or sobol: N points in --box instead of a grid."),
        n: Optional[int] = typer.Option(None, "--n", help="Number of sample points (with --sample) or of throws (with --throw)."),
        box: Optional[str] = typer.Option(None, "--box", help="Sample box (with --sample only): a window name or x0,x1,y0,y1[,z0,z1]."),
        seed: Optional[int] = typer.Option(None, "--seed", help="Seed of the random or scrambled Sobol sample (with --sample) or of the hand throws (with --throw); default 0."),
        points: Optional[Path] = typer.Option(None, "--points", help="CSV of slice coordinates (columns x,y[,z])."),
        throw: Optional[str] = typer.Option(None, "--throw", help=THROW_HELP),
        throws: Optional[Path] = typer.Option(None, "--throws", help=THROWS_HELP),
        origin: Optional[str] = typer.Option(None, "--origin", help="Custom slice origin VX,VY,VZ,LX,LY,LZ."),
        dirs: Optional[List[str]] = typer.Option(None, "--dir", help="Custom slice direction (6 numbers; 1 to 3 times)."),
        preset: str = typer.Option("seed", "--preset", help=PRESET_HELP),
        die: DieOption = None,
        load: LoadOption = None,
        integrator: Optional[str] = typer.Option(None, "--integrator", help=INTEGRATOR_HELP),
        dt: Optional[str] = typer.Option(None, "--dt", help="Time step, s (default 0.001), or 'auto' (chosen from the stiffness k for a 300 cm/s impact; 0.001 for the error-controlled schemes; refused when no step fits)."),
        t_max: Optional[str] = typer.Option(None, "--t-max", help="Time cap, s (default 60)."),
        tol: Optional[str] = typer.Option(None, "--tol", help=TOL_HELP),
        tol_growth: Optional[str] = typer.Option(None, "--tol-growth", help=TOL_GROWTH_HELP),
        sets: Optional[List[str]] = typer.Option(
            None, "--set", help="Override a preset parameter, NAME=VALUE (e.g. gamma=0.01, mu=0.6, k=1e6; the die: "
            "half_extents_cm=X,Y,Z, half the sides that --die takes); repeatable."
        ),
        chunk: Optional[int] = typer.Option(None, "--chunk", help="ICs per chunk file / Dask task (default 8192; "
                                            "262144 on a GPU, whose launches want that many throws)."),
        threads: Optional[int] = typer.Option(None, "--threads", help="numba threads (default: all cores)."),
        device: str = typer.Option("cpu", "--device", help=DEVICE_HELP + " A scan resumes only on the device it started on."),
        dask: bool = typer.Option(False, "--dask", help="Run the chunks on a local Dask cluster (the dask extra)."),
        scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Run the chunks on the Dask scheduler at ADDRESS (the dask extra)."),
        workers: Optional[int] = typer.Option(None, "--workers", help="Worker processes of the --dask cluster (default: one per GPU for a GPU scan, else one per core)."),
        max_chunks: Optional[int] = typer.Option(None, "--max-chunks", help="Stop after this many new chunks (resumable)."),
        rrd: Optional[Path] = typer.Option(None, "--rrd", help="Also write the scan map for the Rerun viewer (.rrd; "
                                           "a device or FIFO directly; '-': stdout)."),
        png: Optional[Path] = typer.Option(None, "--png", help="Also draw the outcome map (2-D grid scans) into a PNG "
                                           "(.png; a device or FIFO directly; '-': stdout)."),
        wait: float = typer.Option(0.0, "--wait", help="Seconds to wait for another scan writing into --out (default 0: refuse at once)."),
        yes: bool = typer.Option(False, "--yes", "-y", help=f"Run even when estimated to take over {MAX_UNCONFIRMED_S / 3600:g} h."),
        strict: bool = typer.Option(False, "--strict", help="Exit 1 when any IC ends in a numerical failure (non_finite, blow_up)."),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar or summary."),
        events: ScanEventsOption = False,
    ) -> None:
        """Scan a slice (grid), a sample or a list of points of IC space, or hand throws; one row per IC."""
        # lazy: keeps `dicetrace --help` fast (imports numba)
        from dicetrace.scan import DEFAULT_CHUNK, GPU_DEFAULT_CHUNK, DeviceMismatchError, ScanDefinition, ScanMismatchError, scan
        from dicetrace.scan.dask import SchedulerError, _open_dask, check_scheduler_address, local_worker_count, worker_device
        from dicetrace.scan.folder import ScanBusyError
        from dicetrace.scan.folder import _check_space_finite

        model = preset_or_fail(preset)  # looked up once: the --set fields, then the config
        changes, renamed = die_overrides(model, die, load, parse_overrides(model, sets or []))
        cfg = build_config(model, integrator, dt, t_max, tol=tol, tol_growth=tol_growth, overrides=changes,
                           renamed=renamed)
        cfg = replace(cfg, preset=plain_body(cfg.preset))  # --die 2,2,2 is the cube: one scan, one definition
        if throws is not None:
            space = throws_space(throws, cfg.preset.l_convention, {
                "--slice": slice_name, "--origin": origin, "--dir": dirs or None, "--window": window, "--z": z,
                "--res": res, "--sample": sample, "--n": n, "--box": box, "--seed": seed, "--points": points,
                "--throw": throw})
        else:
            if throw is not None:
                for name, v in (("--slice", slice_name), ("--origin", origin), ("--dir", dirs or None)):
                    if v is not None:
                        fail(f"{name} gives a slice: --throw scans hand throws, which lie on no slice")
            sl = build_slice(slice_name or "seed", origin, dirs)
            space = build_space(sl, window, z, res, sample, n, box, seed, points, throw)
        if chunk is not None and chunk < 1:
            fail(f"--chunk must be >= 1, got {chunk}")
        if threads is not None and threads < 1:
            fail(f"--threads must be >= 1, got {threads}")
        if workers is not None and workers < 1:
            fail(f"--workers must be >= 1, got {workers}")
        if max_chunks is not None and max_chunks < 0:
            fail(f"--max-chunks must be >= 0, got {max_chunks}")
        if not math.isfinite(wait) or wait < 0:
            fail(f"--wait must be a number of seconds >= 0, got {fmt_num(wait)}")
        if dask and scheduler:
            fail("give --dask (a local cluster) or --scheduler ADDRESS, not both")
        if workers is not None and not dask:
            fail("--workers sets the size of the --dask cluster: add --dask")
        if dask or scheduler is not None:
            require("dask", "--dask" if dask else "--scheduler")
        if scheduler is not None:
            try:
                check_scheduler_address(scheduler)
            except ValueError as e:
                fail(f"--scheduler: {e}")
        events = events_or_fail(cfg, events)
        if png is not None and (space.kind != "grid" or space.ndim < 2):
            fail("--png draws 2-D and 3-D grid scans only (use --rrd for samples, points and 1-D slices)")
        if rrd is not None and space.kind in ("throws", "throw-table"):
            fail("--rrd draws the scan map of a slice: throws from their own poses lie on no slice (record a row "
                 "with dicetrace record --rolls OUT --ic-id N)")
        if scheduler is None:  # here (and a local --dask cluster's workers): resolved now, before any work
            label = device_or_fail(device)
        else:  # the cluster's workers resolve it, once connected (below)
            with config_errors():
                label = "cpu" if check_device(device) == "cpu" else None
        # every output is checked before any work
        out_dir = output_dir(out, "--out")
        png_dest = output_file(png, "--png", suffix=".png") if png is not None else None
        rrd_dest = output_file(rrd, "--rrd", suffix=".rrd") if rrd is not None else None
        if png_dest is not None and rrd_dest is not None and png_dest.kind == rrd_dest.kind == "stdout":
            fail("--png - and --rrd -: only one output can go to standard output")
        if chunk is None:  # resuming: keep the folder's chunk size; a new scan on a GPU: chunks that fill it
            on_gpu = (label or "").startswith("cuda") or (label is None and device == "cuda")
            chunk = _existing_chunk(out) or (GPU_DEFAULT_CHUNK if on_gpu else DEFAULT_CHUNK)
        with config_errors():
            defn = ScanDefinition(space, cfg, chunk, device=label or "cpu", events=events)
        try:
            _check_space_finite(defn)
        except ValueError as e:
            where = {"grid": "--window", "sample": "--box", "throw-table": f"--throws {str(throws)!r}"}.get(
                space.kind, "--points")
            fail(f"{where}: {e}")
        if label is not None:
            _check_out(out_dir, defn)
        maps = [opt for opt, dest in (("--png", png_dest), ("--rrd", rrd_dest)) if dest is not None]
        local = local_worker_count(workers, defn.device) if dask else None
        client, closers = None, []
        if scheduler is not None:  # reached (within DASK_CONNECT_TIMEOUT_S) before anything is computed
            try:
                client, closers = _open_dask(scheduler, None)
            except SchedulerError as e:
                fail(f"--scheduler {scheduler}: {e}")
        try:
            if label is None:  # --device cuda or auto on a --scheduler cluster: as a worker resolves it
                with config_errors():
                    defn = replace(defn, device=worker_device(client, device))
                if device == "auto":
                    say(f"dicetrace: device auto: the Dask workers run on {defn.device}")
                _check_out(out_dir, defn)
            _check_run_size(defn, out_dir, threads, max_chunks, yes, quiet, workers if dask else None, maps=maps,
                            local_workers=local)
            report = scan(
                defn, out_dir, threads=threads, progress=not quiet and stderr_is_terminal(),
                dask=client if client is not None else (True if dask else None), n_workers=local if dask else workers,
                max_chunks=max_chunks, wait=wait,
            )
        except DeviceMismatchError as e:  # the folder changed since the check above
            fail(f"--device: {e}")
        except (ScanMismatchError, FileExistsError) as e:
            fail(f"--out: {e}")
        except DeviceError as e:  # a worker without the scan's GPU
            fail(f"--device: {e}")
        except ScanBusyError as e:
            fail(str(e))
        except SchedulerError as e:
            fail(f"--scheduler {scheduler}: {e}" if scheduler else f"--dask: {e}")
        except KeyboardInterrupt:
            from dicetrace.scan.folder import has_manifest  # loaded already

            say_interrupted(f"dicetrace: interrupted; finished chunks are kept in {str(out)!r}: re-run the same command "
                            "to resume" if has_manifest(out_dir) else
                            f"dicetrace: interrupted before the scan's first chunk: {str(out)!r} holds no scan")
            raise
        finally:
            for x in closers:
                x.close()
        done = report.chunks_skipped + report.chunks_computed
        if not quiet:
            msg = (f"{report.n_ics:,} ICs in {report.n_chunks:,} chunks → {out} (a Parquet dataset: read the folder as it is)  "
                   f"({report.chunks_computed:,} computed, {report.chunks_skipped:,} already there; "
                   f"{rate_text(report.ics_computed, 'ICs', report.wall_s, report.compile_s, ' ICs/s')})")
            say(msg)
            if done < report.n_chunks:
                say(f"{report.n_chunks - done:,} chunks left: re-run the same command to finish")
        failed = _status_summary(out_dir, quiet)
        if png_dest is not None or rrd_dest is not None:
            from dicetrace.scan.map_rrd import write_scan_rrd  # lazy: keeps `dicetrace --help` fast (imports numba)
            from dicetrace.scan.maps import outcome_png

            with Staging() as staging:  # both maps, or neither
                if png_dest is not None:
                    outcome_png(out_dir, png_dest, staging=staging)
                if rrd_dest is not None:
                    write_scan_rrd(out_dir, rrd_dest, staging=staging)
            if not quiet:
                if png_dest is not None:
                    say(f"outcome map → {png}")
                if rrd_dest is not None:
                    say(f"scan map → {rrd} (open with: rerun {rrd})")
        if failed and strict:
            sys.exit(EXIT_NUMERICAL_FAILURE)
