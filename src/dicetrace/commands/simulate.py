"""``dicetrace simulate``: throw the die from one IC or many and print one row per IC.

ICs come from ``--ic VX,VY,VZ,LX,LY,LZ``, from ``--slice seed --at X,Y[,Z]``,
or from ``--ics FILE.csv`` (columns ``vx,vy,vz,Lx,Ly,Lz``, or ``x,y[,z]``
with ``--slice seed``).  All ICs run in one parallel batch
(``simulate_batch``).  Output: ``--format table`` (default), ``csv`` or
``json``, on stdout or atomically into ``--out FILE``.  ``--events`` (the
contact integrators) records the exact contact events: the contact sequence
is then the sets inside the integrator's sub-steps, and a column
``contact_times_s`` says when each began.  A file or pipe gets
every row; a terminal gets the table drawn to fit it, and beyond ``TTY_ROWS``
rows only the first ``TTY_HEAD``, the outcomes of all, and how to get them.

Exit codes: 0 done; 1 some IC ended in a numerical failure (status
``non_finite`` or ``blow_up``: the rows are still printed); 2 bad input.

The options it shares with ``record``, ``scan`` and ``explore`` (their help
texts, ``build_config``, ``ic_from_options``, ...) are in
:mod:`dicetrace.commands.options`.
"""

from __future__ import annotations

import csv
import io
import json
import math
import sys
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

import dicetrace
from dicetrace.commands._common import EXIT_NUMERICAL_FAILURE, fail, output_file
from dicetrace.commands import options as opts
from dicetrace.commands.options import (AT_HELP, IC_HELP, PRESET_HELP, build_config, fmt_num, get_slice,
                                        ic_from_options, preset_or_fail, slice_ics)
from dicetrace.sinks._common import STDOUT, _stdout_open, write_bytes
from dicetrace.status import Status

FORMATS = ("table", "csv", "json")


# -- CSV input -----------------------------------------------------------------------------

_IC_COLS = ("vx", "vy", "vz", "lx", "ly", "lz")
_XYZ = ("x", "y", "z")


def read_ics_csv(path: Path, slice_name: str | None, l_convention: str):
    """ICs from a CSV file: columns vx,vy,vz,Lx,Ly,Lz, or x,y[,z] with a slice.

    Returns (ics (m, 6), coords (m, k) or None).  Columns are matched without
    regard to case; other columns are ignored.  When both kinds are present
    the IC columns are used and x, y, z are kept as the slice coordinates.
    """
    path = Path(path)
    if not path.exists():
        fail(f"IC file {str(path)!r} does not exist")
    if path.is_dir():
        fail(f"IC file {str(path)!r} is a folder")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        fail(f"IC file {str(path)!r} is not a UTF-8 text (CSV) file")
    except OSError as e:
        fail(f"cannot read IC file {str(path)!r}: {e.strerror}")
    rows = [r for r in csv.reader(io.StringIO(text)) if any(c.strip() for c in r)]
    if not rows:
        fail(f"IC file {str(path)!r} is empty (expected a header vx,vy,vz,Lx,Ly,Lz or x,y)")
    header = [h.strip().lower() for h in rows[0]]
    data = rows[1:]
    if not data:
        fail(f"IC file {str(path)!r} has a header but no rows")
    dup = sorted({h for h in header if header.count(h) > 1 and h in _IC_COLS + _XYZ})
    if dup:
        fail(f"IC file {str(path)!r}: repeated column(s) {', '.join(dup)}")
    has_ic = all(c in header for c in _IC_COLS)
    has_xy = "x" in header and "y" in header
    if not has_ic and not has_xy:
        fail(
            f"IC file {str(path)!r} needs columns vx,vy,vz,Lx,Ly,Lz or x,y (with --slice seed); "
            f"found {', '.join(h or '?' for h in header)}"
        )
    if not has_ic and slice_name is None:
        fail(f"IC file {str(path)!r} gives slice coordinates x,y: add --slice seed")
    if slice_name is not None:
        get_slice(slice_name)
    want = list(_IC_COLS) if has_ic else []
    coord_cols = [c for c in _XYZ if c in header] if has_xy else []
    idx = {c: header.index(c) for c in want + coord_cols}
    vals = np.empty((len(data), len(want) + len(coord_cols)))
    for i, row in enumerate(data):
        line = i + 2
        if len(row) != len(header):
            fail(f"IC file {str(path)!r}, line {line}: {len(row)} fields, the header has {len(header)}")
        for j, c in enumerate(want + coord_cols):
            cell = row[idx[c]].strip()
            try:
                v = float(cell)
            except ValueError:
                fail(f"IC file {str(path)!r}, line {line}, column {c}: not a number: {cell!r}")
            if not math.isfinite(v):
                fail(f"IC file {str(path)!r}, line {line}, column {c}: not finite: {cell!r}")
            vals[i, j] = v
    coords = vals[:, len(want) :] if coord_cols else None
    if has_ic:
        return vals[:, : len(want)], coords
    return slice_ics(slice_name, coords, l_convention, what=f"IC file {str(path)!r}, a row at"), coords


def run_ics(ics: np.ndarray, cfg, events: bool = False):
    """Summaries of every IC as a BatchResult: one parallel batch, or a plain ``simulate`` for a single IC.

    (Both are bit-identical; the single throw skips the batch's thread start-up.)  ``events`` (``--events``):
    with the exact contact events and their times (``BatchResult.set_times``), ``Record.events_only()``.
    """
    # lazy: keeps `dicetrace --help` fast (imports numba)
    from dicetrace.simulate import BatchResult, Record, simulate, simulate_batch

    record = Record.events_only() if events else None
    if len(ics) != 1:
        return simulate_batch(ics, config=cfg, record=record)
    r = simulate(ics[0], config=cfg, record=record)
    return BatchResult(
        ics=ics.copy(),
        outcome=np.array([r.outcome], dtype=np.int8),
        status_code=np.array([r.status], dtype=np.int8),
        steps=np.array([r.steps], dtype=np.int64),
        t_settle_s=np.array([r.t_settle_s]),
        set_offsets=np.array([0, len(r.contact_sets)], dtype=np.int64),
        sets=r.contact_sets,
        set_steps=r.contact_steps,
        config=cfg,
        set_times=r.contact_times,
    )


# -- output ---------------------------------------------------------------------------------


def result_rows(batch, coords) -> tuple[list[str], list[list]]:
    """Column names and rows (python values) of a batch's summaries."""
    names = ["ic_id"]
    ncoord = 0 if coords is None else coords.shape[1]
    names += list(_XYZ[:ncoord])
    names += ["vx", "vy", "vz", "Lx", "Ly", "Lz", "outcome", "steps", "t_settle_s", "status", "contact_sequence"]
    times = batch.set_times
    if times is not None:
        names.append("contact_times_s")
    seqs = batch.contact_sequences()
    rows = []
    for i in range(len(batch)):
        row = [i]
        if ncoord:
            row += [float(v) for v in coords[i]]
        row += [float(v) for v in batch.ics[i]]
        row += [
            int(batch.outcome[i]),
            int(batch.steps[i]),
            float(batch.t_settle_s[i]),
            Status(int(batch.status_code[i])).label,
            seqs[i],
        ]
        if times is not None:
            row.append(Times(times[batch.set_offsets[i]:batch.set_offsets[i + 1]].tolist()))
        rows.append(row)
    return names, rows


#: Columns right-aligned in the table.
_NUMERIC = frozenset({"ic_id", "x", "y", "z", "vx", "vy", "vz", "Lx", "Ly", "Lz", "outcome", "steps", "t_settle_s"})
#: On a terminal the table shows at most this many rows (drawn to fit it); beyond, the first TTY_HEAD rows,
#: how many more there are, their outcomes, and how to get them all.
TTY_ROWS = 60
TTY_HEAD = 20


class Times(list):
    """The times (s) at which a throw's contact sets began: a list in JSON, space-separated in a table or CSV."""

    def text(self, num=repr) -> str:
        return " ".join(num(t) for t in self)


def _cells(rows) -> list[list[str]]:
    return [[fmt_num(v) if isinstance(v, float) else v.text(fmt_num) if isinstance(v, Times) else str(v) for v in r]
            for r in rows]


def plain_table(names, rows) -> str:
    """The table as fixed-width text: the columns of rich's borderless table, two spaces apart (any number of rows).

    Numbers are right-aligned, text left-aligned, no trailing spaces; it
    costs a string join per row (rich's layout engine took ~1 ms a row).
    """
    cells = _cells(rows)
    widths = [len(n) for n in names]
    for r in cells:
        for j, v in enumerate(r):
            if len(v) > widths[j]:
                widths[j] = len(v)
    right = [n in _NUMERIC for n in names]

    def line(vals) -> str:
        return "  ".join(v.rjust(w) if rj else v.ljust(w) for v, w, rj in zip(vals, widths, right)).rstrip()

    return "".join(line(r) + "\n" for r in [list(names), *cells])


def terminal_table(names, rows, stream) -> None:
    """The table on a terminal: rich's, fitted to its width; beyond TTY_ROWS rows only the first, a count and a hint."""
    shown = rows if len(rows) <= TTY_ROWS else rows[:TTY_HEAD]
    table = Table(box=None, header_style="bold", pad_edge=False)
    for n in names:
        table.add_column(n, justify="right" if n in _NUMERIC else "left", overflow="fold")
    for r in _cells(shown):
        table.add_row(*r)
    console = Console(file=stream, highlight=False)
    console.print(table)
    if len(shown) < len(rows):
        j = names.index("outcome")
        counts: dict = {}
        for r in rows:
            counts[r[j]] = counts.get(r[j], 0) + 1
        faces = ", ".join(f"{'face ' + str(k) if k > 0 else 'undefined' if k == 0 else 'not settled'}: "
                          f"{100 * v / len(rows):.1f}%" for k, v in sorted(counts.items(), key=lambda kv: (kv[0] <= 0, kv[0])))
        console.print(f"… and {len(rows) - len(shown):,} more rows (outcomes of all {len(rows):,}: {faces}).\n"
                      "All rows: --format csv or json, or --out FILE (the table, in full).", highlight=False, markup=False)


def render(names, rows, fmt: str, stream, *, meta: dict) -> None:
    """Every row, as ``fmt`` (table, csv or json), into a text stream."""
    if fmt == "csv":
        w = csv.writer(stream, lineterminator="\n")
        w.writerow(names)
        for r in rows:
            w.writerow([repr(v) if isinstance(v, float) else v.text() if isinstance(v, Times) else v for v in r])
    elif fmt == "json":
        doc = {**meta, "columns": names, "rolls": [dict(zip(names, r)) for r in rows]}
        json.dump(doc, stream, indent=1)
        stream.write("\n")
    else:
        stream.write(plain_table(names, rows))


def emit(names, rows, fmt: str, out, *, meta: dict) -> None:
    """Print the rows, or write them to ``out`` (a checked Destination or a path; atomically for a regular file)."""
    if out is None or str(getattr(out, "given", out)) == STDOUT:
        if fmt == "table" and sys.stdout.isatty():
            terminal_table(names, rows, sys.stdout)
            return
        out = STDOUT
    buf = io.StringIO()
    render(names, rows, fmt, buf, meta=meta)
    write_bytes(out, buf.getvalue().encode("utf-8"), what="--out")


def report_failures(statuses, what: str = "IC") -> bool:
    """One line on stderr if any run failed numerically; True if so."""
    statuses = [Status.from_label(s) if isinstance(s, str) else Status(int(s)) for s in statuses]
    bad = [s for s in statuses if s.failed]
    if not bad:
        return False
    kinds = sorted(set(bad))
    counts = ", ".join(f"{k.label}: {bad.count(k)}" for k in kinds)
    advice = kinds[0].advice
    print(
        f"dicetrace: numerical failure: {len(bad)} of {len(statuses)} {what}(s) failed ({counts}): {advice}",
        file=sys.stderr,
    )
    return True


# -- the command ----------------------------------------------------------------------------


def register(app: typer.Typer) -> None:
    @app.command("simulate")
    def simulate_cmd(
        ic: Optional[str] = typer.Option(None, "--ic", help=IC_HELP),
        slice_name: opts.SliceOption = None,
        at: Optional[str] = typer.Option(None, "--at", help=AT_HELP),
        ics: Optional[Path] = typer.Option(
            None, "--ics", help="CSV file of ICs: columns vx,vy,vz,Lx,Ly,Lz, or x,y[,z] with --slice seed."
        ),
        preset: str = typer.Option("seed", "--preset", help=PRESET_HELP),
        integrator: opts.IntegratorOption = None,
        dt: opts.DtOption = None,
        t_max: opts.TMaxOption = None,
        tol: opts.TolOption = None,
        tol_growth: opts.TolGrowthOption = None,
        die: opts.DieOption = None,
        load: opts.LoadOption = None,
        fmt: str = typer.Option("table", "--format", help="Output format: table, csv or json. On a terminal a table of more "
                               f"than {TTY_ROWS} rows shows the first {TTY_HEAD} and the outcomes of all; a file "
                               "or pipe gets every row."),
        out: Optional[Path] = typer.Option(
            None, "--out", help="Write the output to this file (atomically; a device or FIFO directly; '-': stdout) "
            "instead of stdout."
        ),
        events: opts.SimulateEventsOption = False,
        yes: opts.YesOption = False,
    ) -> None:
        """Throw the die from one or many ICs; print outcome, steps, t_settle_s, status and contact sequence per IC.

        Exit code 1 when an IC ends in a numerical failure (non_finite, blow_up), 2 on bad input.
        """
        if fmt not in FORMATS:
            fail(f"unknown --format {fmt!r} (choose from {', '.join(FORMATS)})")
        if out is None:
            if not _stdout_open():
                fail("standard output is closed: give --out FILE")
        dest = output_file(out if out is not None else STDOUT, "--out")
        model = preset_or_fail(preset)  # looked up once: its L convention reads the ICs, then the config
        if ics is not None:
            if ic is not None or at is not None:
                fail("give one source of ICs: --ics FILE, --ic, or --slice/--at")
            ic_arr, coords = read_ics_csv(ics, slice_name, model.l_convention)
            source = {"ics_file": str(ics)}
        else:
            one, c, desc = ic_from_options(ic, slice_name, at, model.l_convention)
            ic_arr = one[None, :]
            coords = None if c is None else c[None, :]
            source = desc
        cfg = build_config(model, integrator, dt, t_max, ics=ic_arr, tol=tol, tol_growth=tol_growth,
                           overrides=opts.body_overrides(die, load))
        opts.events_or_fail(cfg, events)
        opts.long_throw_or_fail(cfg, yes)
        batch = run_ics(ic_arr, cfg, events)
        names, rows = result_rows(batch, coords)
        meta = {
            "dicetrace_version": dicetrace.__version__,
            "config": cfg.as_dict(),
            "source": {**source, **({"slice": slice_name} if slice_name else {})},
        }
        emit(names, rows, fmt, dest, meta=meta)
        if report_failures(batch.status):
            sys.exit(EXIT_NUMERICAL_FAILURE)  # (typer.Exit is swallowed outside standalone mode)
