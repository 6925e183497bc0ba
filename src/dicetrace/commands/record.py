"""``dicetrace record``: simulate one throw and write it as a Rerun ``.rrd`` (and Parquet).

The IC comes from ``--ic VX,VY,VZ,LX,LY,LZ``, ``--slice seed --at X,Y[,Z]``,
or ``--scan DIR --at X,Y`` (the scanned point nearest to X,Y, with the
scan's configuration: it reproduces that row exactly).
The recording goes to ``--out PATH.rrd``, by default
``recordings/<name>.rrd`` where the name encodes the IC
(``seed_x1.65_y3.9.rrd``, ``ic_1_2_3_4_5_6.rrd``, plus the preset,
integrator and time step when they are not the defaults).  ``--parquet DIR``
also writes ``rolls.parquet``, ``contacts.parquet`` and
``trajectory.parquet`` there.  Prints one summary line.

Exit codes: 0 done (settled or time cap); 1 numerical failure (status
``non_finite`` or ``blow_up``: the files are still written, for inspection);
2 bad input (nothing written).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Optional

import typer

import numpy as np

from dicetrace.commands._common import fail, output_dir, parse_floats
from dicetrace.commands.simulate import (
    AT_HELP,
    DT_HELP,
    EXIT_NUMERICAL_FAILURE,
    IC_HELP,
    INTEGRATOR_HELP,
    TOL_HELP,
    PRESET_HELP,
    SLICE_HELP,
    T_MAX_HELP,
    build_config,
    check_output_file,
    fmt_num,
    ic_from_options,
    preset_or_fail,
)

DEFAULT_FOLDER = Path("recordings")


def default_name(ic, coords, desc: dict, cfg) -> str:
    """File stem encoding the IC (and any non-default preset, integrator, time step)."""
    from dicetrace.params import Numerics

    if desc.get("kind") == "scan":
        parts = [Path(desc["scan"]).resolve().name or "scan"] + [f"{a}{fmt_num(v)}" for a, v in zip("xyz", coords)]
    elif desc.get("kind") == "slice":
        parts = [desc["slice"]] + [f"{a}{fmt_num(v)}" for a, v in zip("xyz", coords)]
    else:
        parts = ["ic"] + [fmt_num(v) for v in ic]
    default = Numerics()
    if cfg.preset.name != "seed":
        parts.append(cfg.preset.name)
    if cfg.numerics.integrator != default.integrator:
        parts.append(cfg.numerics.integrator)
    if cfg.numerics.dt_s != default.dt_s:
        parts.append(f"dt{fmt_num(cfg.numerics.dt_s)}")
    return "_".join(parts)


def ic_label(ic, coords, desc: dict) -> str:
    if desc.get("kind") == "scan":
        where = ", ".join(f"{a} = {fmt_num(v)}" for a, v in zip("xyz", coords))
        return f"scan {desc['scan']} (slice {desc['slice']}) at {where}, ic_id {desc['ic_id']}"
    if desc.get("kind") == "slice":
        return f"{desc['slice']} slice at " + ", ".join(f"{a} = {fmt_num(v)}" for a, v in zip("xyz", coords))
    return "given directly: " + ", ".join(fmt_num(v) for v in ic)


def check_output_folder(path: Path) -> Path:
    """Fail (exit 2) unless ``path`` is, or can be made, a writable folder whose table files can be written.

    Nothing is created: the folder is made when the tables are written.
    """
    path = output_dir(path, "--parquet")
    for name in ("rolls", "contacts", "trajectory"):
        dest = check_output_file(path / f"{name}.parquet", "--parquet")
        if dest.kind != "file":
            fail(f"--parquet {str(path)!r}: {name}.parquet is not a regular file")
    return path


#: Peak memory of ``record`` per step of the throw, in units of its trace arrays (the trace, the
#: recording's per-step arrays while logging, the encoded recording).
RECORD_MEMORY_FACTOR = 8.0


def check_record_size(cfg) -> None:
    """Refuse, before running, a throw whose recording could exceed the available memory.

    The worst case is a throw that runs to the time cap: max_steps + 1 rows.
    """
    from dicetrace.simulate import Record, available_memory, trace_bytes
    from dicetrace.sinks._common import human_bytes

    steps = cfg.numerics.max_steps
    need = trace_bytes(steps + 1, Record(states=True, energy=True)) * RECORD_MEMORY_FACTOR
    avail = available_memory()
    if avail is not None and need > avail:
        fail(f"--dt {fmt_num(cfg.numerics.dt_s)} / --t-max {fmt_num(cfg.numerics.t_max_s)}: a throw may run to the "
             f"time cap, {steps:,} steps, whose recording needs up to {human_bytes(need)} of memory, more than the "
             f"{human_bytes(avail)} available: use a larger --dt or a shorter --t-max")


def ic_from_scan(folder: Path, at: str | None, conflicting: dict):
    """The IC of a scanned point (nearest grid point to ``--at``) and the scan's configuration.

    Returns (ic, config, coords, description dict).
    """
    if at is None:
        fail("--scan needs --at X,Y (the slice coordinates of a scanned point)")
    given = [opt for opt, v in conflicting.items() if v is not None]
    if given:
        fail(f"--scan takes the IC and the configuration from the scan: drop {', '.join(given)}")
    folder = Path(folder)
    if not folder.is_dir():
        fail(f"--scan {str(folder)!r} is not a folder")
    coords = parse_floats(at, None, "--at")
    try:
        from dicetrace.scan import ic_at, scan_definition

        the_ic, cfg, row = ic_at(folder, coords)
        slice_name = scan_definition(folder).space.slice.name
    except (ValueError, KeyError, OSError) as e:
        fail(f"--scan {str(folder)!r} --at {at}: {e}")
    ndim = len(coords)
    exact = np.array([row[a] for a in "xyz"[:ndim]], dtype=np.float64)
    desc = {"kind": "scan", "slice": slice_name, "scan": str(folder), "ic_id": int(row["ic_id"])}
    return np.asarray(the_ic, dtype=np.float64), cfg, exact, desc


def register(app: typer.Typer) -> None:
    @app.command("record")
    def record_cmd(
        ic: Optional[str] = typer.Option(None, "--ic", help=IC_HELP),
        slice_name: Optional[str] = typer.Option(None, "--slice", help=SLICE_HELP),
        at: Optional[str] = typer.Option(None, "--at", help=AT_HELP + " With --scan: a scanned point (the nearest one)."),
        scan: Optional[Path] = typer.Option(
            None, "--scan", help="A scan folder (dicetrace scan): record its point nearest to --at, with its configuration."
        ),
        preset: Optional[str] = typer.Option(None, "--preset", help=PRESET_HELP + " [default: seed]"),
        integrator: Optional[str] = typer.Option(None, "--integrator", help=INTEGRATOR_HELP),
        dt: Optional[str] = typer.Option(None, "--dt", help=DT_HELP),
        t_max: Optional[str] = typer.Option(None, "--t-max", help=T_MAX_HELP),
        tol: Optional[str] = typer.Option(None, "--tol", help=TOL_HELP),
        out: Optional[Path] = typer.Option(
            None, "--out", help="Output .rrd file (default: recordings/<name>.rrd, the name encoding the IC); "
            "a character device or FIFO is written directly, '-' is standard output."
        ),
        parquet: Optional[Path] = typer.Option(
            None, "--parquet", help="Also write rolls.parquet, contacts.parquet and trajectory.parquet into this folder."
        ),
    ) -> None:
        """Simulate one throw and write it as a Rerun recording (.rrd) with a default blueprint.

        Open it with `rerun FILE.rrd`.  Exit code 1 on a numerical failure (the files are
        still written for inspection), 2 on bad input.
        """
        if scan is not None:
            if ic is not None or slice_name is not None:
                fail("give either --scan DIR --at X,Y or --ic / --slice, not both")
            conflicting = {"--preset": preset, "--integrator": integrator, "--dt": dt, "--t-max": t_max, "--tol": tol}
            the_ic, cfg, coords, desc = ic_from_scan(scan, at, conflicting)
        else:
            conv = preset_or_fail(preset or "seed").l_convention
            the_ic, coords, desc = ic_from_options(ic, slice_name, at, conv)
            cfg = build_config(preset or "seed", integrator, dt, t_max, ics=the_ic, tol=tol)
        name = default_name(the_ic, coords, desc, cfg)
        if out is None:
            out = DEFAULT_FOLDER / f"{name}.rrd"
        dest = check_output_file(out, "--out", suffix=".rrd")
        if parquet is not None:
            check_output_folder(parquet)
            if dest.target is not None and os.path.realpath(parquet) == os.path.realpath(dest.target):
                fail(f"--out {str(out)!r} and --parquet {str(parquet)!r} are the same path")
        check_record_size(cfg)

        from dicetrace.simulate import Record, simulate

        roll = simulate(the_ic, config=cfg, record=Record(states=True, energy=True))
        label = ic_label(the_ic, coords, desc)

        from dicetrace.sinks._common import Staging
        from dicetrace.sinks.rerun import encode_rrd_of

        # Everything is staged first and put in place together: a failure (a full
        # disk) leaves neither a half-written file nor a recording without its tables.
        with Staging() as staging:
            data = encode_rrd_of(roll, name=name, ic_label=label)
            tmp = staging.path(dest)
            try:
                tmp.write_bytes(data)
            except OSError as e:
                raise staging.fail(dest, e) from None
            written = [dest.label if dest.kind == "stdout" else str(out)]
            if parquet is not None:
                from dicetrace.sinks.parquet import write_tables

                meta = {"ic_label": label, **{k: v for k, v in desc.items() if k != "kind"}}
                ids = [desc["ic_id"]] if "ic_id" in desc else None
                coords2 = None if coords is None else coords[None, :]
                paths = write_tables(parquet, roll, coords=coords2, ic_ids=ids, metadata=meta, staging=staging)
                written.append(f"{parquet}{os.sep} ({', '.join(p.name for p in paths.values())})")

        outcome = roll.outcome if roll.outcome >= 0 else "-1 (not settled)"
        summary = (
            f"outcome {outcome}  status {roll.status}  steps {roll.steps}  t_settle_s {roll.t_settle_s:.6g}  "
            f"contact_sequence {roll.contact_sequence}  wrote {' '.join(written)}"
        )
        # the recording itself may be on stdout: the summary then goes to stderr
        stream = sys.stderr if dest.kind == "stdout" or sys.stdout is None else sys.stdout
        print(summary, file=stream)
        if roll.status.failed:
            print(
                f"dicetrace: numerical failure: status {roll.status} after {roll.steps} steps "
                f"(t = {roll.t_settle_s:.6g} s): {roll.status.advice}; "
                f"the recording was still written for inspection: {out}",
                file=sys.stderr,
            )
            sys.exit(EXIT_NUMERICAL_FAILURE)
